// ICM-20948 9-axis driver over I2C or SPI. The AK09916 magnetometer is read through the
// ICM-20948's auxiliary I2C master (not bypass mode): the master copies the magnetometer's
// 9-byte status+data block into EXT_SLV_SENS_DATA at each of its cycles, so one burst read of
// 23 bytes from ACCEL_XOUT_H gives accel, gyro, temperature and magnetometer, and the same code
// works on SPI, where bypass mode would not reach the magnetometer at all.
#pragma once

#include <memory>

#include "hal/drivers/icm20948_registers.h"
#include "hal/drivers/imu_driver.h"
#include "hal/drivers/register_io.h"

namespace caphub::hal {

class Icm20948 final : public ImuDriver {
public:
    enum class Interface { I2c, Spi };

    Icm20948(std::unique_ptr<RegisterIo> io, Interface iface, std::string name,
             const ImuConfig& config);

    int probe() override;
    int readSample(Timestamp t, ImuSample& out) override;
    int dataReady(bool& ready) override;

    // Register access by bank-typed register: selects the bank, then returns to bank 0, so the
    // chip is left in bank 0 (also what a chip that reset itself is in).
    template <typename Reg>
    [[nodiscard]] int read(Reg reg, std::uint8_t& value) {
        return readRegister(static_cast<std::uint8_t>(icm20948::bankOf(reg)),
                            static_cast<std::uint8_t>(reg), value);
    }
    template <typename Reg>
    [[nodiscard]] int write(Reg reg, std::uint8_t value) {
        return writeRegister(static_cast<std::uint8_t>(icm20948::bankOf(reg)),
                             static_cast<std::uint8_t>(reg), value);
    }

    // The divider settings and filters chosen for config() (exposed for tests and status).
    static int gyroDivider(double odrHz);
    static int accelDivider(double odrHz);
    static int dlpfConfigFor(double odrHz, bool gyro);

    // Reads or writes one AK09916 register through the auxiliary master's slave 4.
    [[nodiscard]] int magRead(std::uint8_t reg, std::uint8_t& value);
    [[nodiscard]] int magWrite(std::uint8_t reg, std::uint8_t value);

protected:
    int softReset() override;
    Duration resetDelay() const override { return std::chrono::milliseconds(100); }
    int buildSettings(SettingTable& table) override;
    int readRegister(std::uint8_t bank, std::uint8_t reg, std::uint8_t& value) override;
    int writeRegister(std::uint8_t bank, std::uint8_t reg, std::uint8_t value) override;
    int afterConfigure() override;

private:
    int selectBank(std::uint8_t bank);
    int slave4(bool read, std::uint8_t reg, std::uint8_t& value);

    std::unique_ptr<RegisterIo> io_;
    Interface iface_;
    double accelLsbPerG_ = 2048;
    double gyroLsbPerDps_ = 16.4;
};

}  // namespace caphub::hal
