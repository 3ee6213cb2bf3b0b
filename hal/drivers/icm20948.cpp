#include "hal/drivers/icm20948.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "hal/drivers/ak09916_registers.h"

namespace caphub::hal {

using namespace icm20948;

namespace {

int rangeIndex(const double (&ranges)[4], double value) {
    for (int i = 0; i < 4; ++i) {
        if (ranges[i] == value) {
            return i;
        }
    }
    return -1;
}

// 3 dB bandwidths of the DLPF settings 0-7 (datasheet tables 16 and 18), Hz.
constexpr double kGyroDlpfHz[8] = {196.6, 151.8, 119.5, 51.2, 23.9, 11.6, 5.7, 361.4};
constexpr double kAccelDlpfHz[8] = {246.0, 246.0, 111.4, 50.4, 23.9, 11.5, 5.7, 473.0};

ak09916::Mode magMode(double hz) {
    if (hz >= 100) {
        return ak09916::Mode::Continuous100Hz;
    }
    if (hz >= 50) {
        return ak09916::Mode::Continuous50Hz;
    }
    if (hz >= 20) {
        return ak09916::Mode::Continuous20Hz;
    }
    return ak09916::Mode::Continuous10Hz;
}

}  // namespace

Icm20948::Icm20948(std::unique_ptr<RegisterIo> io, Interface iface, std::string name,
                   const ImuConfig& config)
    : ImuDriver(std::move(name), config), io_(std::move(io)), iface_(iface) {}

int Icm20948::gyroDivider(double odrHz) {
    return static_cast<int>(std::clamp(std::round(kGyroBaseRateHz / odrHz - 1.0), 0.0, 255.0));
}

int Icm20948::accelDivider(double odrHz) {
    return static_cast<int>(std::clamp(std::round(kAccelBaseRateHz / odrHz - 1.0), 0.0, 4095.0));
}

// The widest filter whose bandwidth stays below half the output rate (no aliasing).
int Icm20948::dlpfConfigFor(double odrHz, bool gyro) {
    const double* bw = gyro ? kGyroDlpfHz : kAccelDlpfHz;
    int best = 6;  // the narrowest, 5.7 Hz
    for (int cfg = 0; cfg < 7; ++cfg) {
        if (bw[cfg] < 0.5 * odrHz && bw[cfg] > bw[best]) {
            best = cfg;
        }
    }
    return best;
}

int Icm20948::selectBank(std::uint8_t bank) {
    return io_->write(kRegBankSel, bankSelValue(bank));
}

int Icm20948::readRegister(std::uint8_t bank, std::uint8_t reg, std::uint8_t& value) {
    if (bank == 0) {
        return io_->readByte(reg, value);
    }
    if (int r = selectBank(bank); r < 0) {
        return r;
    }
    const int r = io_->readByte(reg, value);
    const int back = selectBank(0);
    return r < 0 ? r : back;
}

int Icm20948::writeRegister(std::uint8_t bank, std::uint8_t reg, std::uint8_t value) {
    if (bank == 0) {
        return io_->write(reg, value);
    }
    if (int r = selectBank(bank); r < 0) {
        return r;
    }
    const int r = io_->write(reg, value);
    const int back = selectBank(0);
    return r < 0 ? r : back;
}

int Icm20948::probe() {
    // After a reset the chip is in bank 0, but a warm start may find it anywhere.
    if (int r = selectBank(0); r < 0) {
        return r;
    }
    std::uint8_t who = 0;
    if (int r = read(Bank0::WHO_AM_I, who); r < 0) {
        return r;
    }
    return who == kWhoAmI ? 0 : -ENODEV;
}

int Icm20948::softReset() {
    return write(Bank0::PWR_MGMT_1, pwr_mgmt_1::DEVICE_RESET);
}

int Icm20948::buildSettings(SettingTable& t) {
    const ImuConfig& c = config();
    const int gyroFs = rangeIndex(kGyroRangeDps, c.gyroRangeDps);
    const int accelFs = rangeIndex(kAccelRangeG, c.accelRangeG);
    if (gyroFs < 0 || accelFs < 0 || !(c.odrHz > 0)) {
        return -EINVAL;
    }
    accelLsbPerG_ = kAccelLsbPerG[accelFs];
    gyroLsbPerDps_ = kGyroLsbPerDps[gyroFs];
    const int gdiv = gyroDivider(c.odrHz);
    const int adiv = accelDivider(c.odrHz);
    const auto full = [](std::uint8_t v) { return static_cast<std::uint8_t>(~v); };
    const auto b0 = [](Bank0 r) { return static_cast<std::uint8_t>(r); };
    const auto b2 = [](Bank2 r) { return static_cast<std::uint8_t>(r); };
    const auto b3 = [](Bank3 r) { return static_cast<std::uint8_t>(r); };

    const std::uint8_t userCtrl =
        user_ctrl::I2C_MST_EN | (iface_ == Interface::Spi ? user_ctrl::I2C_IF_DIS : 0);
    const std::uint8_t gyroCfg = static_cast<std::uint8_t>(dlpfcfg(dlpfConfigFor(c.odrHz, true)) |
                                                           fsSel(gyroFs) | gyro_config_1::FCHOICE);
    const std::uint8_t accelCfg = static_cast<std::uint8_t>(dlpfcfg(dlpfConfigFor(c.odrHz, false)) |
                                                            fsSel(accelFs) | accel_config::FCHOICE);
    const std::uint8_t intEnable = c.dataReadyInterrupt ? RAW_DATA_0_RDY : 0;

    std::size_t n = 0;
    auto add = [&](std::uint8_t bank, std::uint8_t reg, std::uint8_t set, std::uint8_t clear) {
        t[n++] = RegisterSetting{bank, reg, set, clear};
    };
    // Wake with the best clock; no low-power cycling; every axis on.
    add(0, b0(Bank0::PWR_MGMT_1), pwr_mgmt_1::CLKSEL_AUTO,
        pwr_mgmt_1::DEVICE_RESET | pwr_mgmt_1::SLEEP | pwr_mgmt_1::LP_EN | pwr_mgmt_1::TEMP_DIS |
            0x06);
    add(0, b0(Bank0::PWR_MGMT_2), 0, 0x3F);
    add(0, b0(Bank0::LP_CONFIG), 0, 0x70);
    add(0, b0(Bank0::USER_CTRL), userCtrl,
        static_cast<std::uint8_t>(user_ctrl::DMP_EN | user_ctrl::FIFO_EN |
                                  (iface_ == Interface::I2c ? user_ctrl::I2C_IF_DIS : 0)));
    // INT1: active high, push-pull, 50 us pulse per sample (not latched); no bypass.
    add(0, b0(Bank0::INT_PIN_CFG), 0,
        int_pin_cfg::INT1_ACTL | int_pin_cfg::INT1_OPEN | int_pin_cfg::INT1_LATCH_EN |
            int_pin_cfg::BYPASS_EN);
    add(0, b0(Bank0::INT_ENABLE_1), intEnable, full(intEnable));
    add(2, b2(Bank2::GYRO_SMPLRT_DIV), static_cast<std::uint8_t>(gdiv),
        full(static_cast<std::uint8_t>(gdiv)));
    add(2, b2(Bank2::GYRO_CONFIG_1), gyroCfg, full(gyroCfg));
    add(2, b2(Bank2::ACCEL_SMPLRT_DIV_1), static_cast<std::uint8_t>(adiv >> 8),
        full(static_cast<std::uint8_t>(adiv >> 8)));
    add(2, b2(Bank2::ACCEL_SMPLRT_DIV_2), static_cast<std::uint8_t>(adiv & 0xFF),
        full(static_cast<std::uint8_t>(adiv & 0xFF)));
    add(2, b2(Bank2::ACCEL_CONFIG), accelCfg, full(accelCfg));
    add(2, b2(Bank2::ODR_ALIGN_EN), 0x01, 0);
    // Auxiliary master at 345.6 kHz, stop between reads; its own rate 1.1 kHz / 2^3 = 137.5 Hz,
    // above the AK09916's fastest mode.
    add(3, b3(Bank3::I2C_MST_CTRL), I2C_MST_CLK_345KHZ | 0x10, 0x80 | 0x08);
    add(3, b3(Bank3::I2C_MST_ODR_CONFIG), 0x03, full(0x03));
    // Slave 0: read ST1..ST2 (9 bytes) of the AK09916 every master cycle.
    add(3, b3(Bank3::I2C_SLV0_ADDR), I2C_SLV_RNW | ak09916::kI2cAddress,
        full(I2C_SLV_RNW | ak09916::kI2cAddress));
    add(3, b3(Bank3::I2C_SLV0_REG), static_cast<std::uint8_t>(ak09916::Register::ST1),
        full(static_cast<std::uint8_t>(ak09916::Register::ST1)));
    add(3, b3(Bank3::I2C_SLV0_CTRL), slv_ctrl::EN | ak09916::kBlockLength,
        full(slv_ctrl::EN | ak09916::kBlockLength));
    return static_cast<int>(n);
}

int Icm20948::slave4(bool isRead, std::uint8_t reg, std::uint8_t& value) {
    const std::uint8_t addr =
        static_cast<std::uint8_t>(ak09916::kI2cAddress | (isRead ? I2C_SLV_RNW : 0));
    if (int r = write(Bank3::I2C_SLV4_ADDR, addr); r < 0) {
        return r;
    }
    if (int r = write(Bank3::I2C_SLV4_REG, reg); r < 0) {
        return r;
    }
    if (!isRead) {
        if (int r = write(Bank3::I2C_SLV4_DO, value); r < 0) {
            return r;
        }
    }
    if (int r = write(Bank3::I2C_SLV4_CTRL, slv_ctrl::EN); r < 0) {
        return r;
    }
    // The master completes within one of its cycles (~7 ms at 137.5 Hz): poll the done bit a
    // bounded number of times; each poll is one bus transaction.
    for (int attempt = 0; attempt < 200; ++attempt) {
        std::uint8_t status = 0;
        if (int r = read(Bank0::I2C_MST_STATUS, status); r < 0) {
            return r;
        }
        if ((status & I2C_SLV4_NACK) != 0) {
            return -ENXIO;
        }
        if ((status & I2C_SLV4_DONE) != 0) {
            return isRead ? read(Bank3::I2C_SLV4_DI, value) : 0;
        }
    }
    return -ETIMEDOUT;
}

int Icm20948::magRead(std::uint8_t reg, std::uint8_t& value) {
    return slave4(true, reg, value);
}

int Icm20948::magWrite(std::uint8_t reg, std::uint8_t value) {
    return slave4(false, reg, value);
}

int Icm20948::afterConfigure() {
    std::uint8_t wia2 = 0;
    if (int r = magRead(static_cast<std::uint8_t>(ak09916::Register::WIA2), wia2); r < 0) {
        return r;
    }
    if (wia2 != ak09916::kDeviceId) {
        return -ENODEV;
    }
    std::uint8_t mode = static_cast<std::uint8_t>(magMode(config().magOdrHz));
    return magWrite(static_cast<std::uint8_t>(ak09916::Register::CNTL2), mode);
}

int Icm20948::dataReady(bool& ready) {
    std::uint8_t status = 0;
    const int r = read(Bank0::INT_STATUS_1, status);
    ready = r == 0 && (status & RAW_DATA_0_RDY) != 0;
    return r;
}

int Icm20948::readSample(Timestamp t, ImuSample& out) {
    SampleBurst b{};
    auto* bytes = reinterpret_cast<std::uint8_t*>(&b);
    if (int r = io_->read(static_cast<std::uint8_t>(Bank0::ACCEL_XOUT_H),
                          std::span<std::uint8_t>(bytes, sizeof b));
        r < 0) {
        counters_.bump(counters_.readErrors);
        return r;
    }
    out.t = t;
    out.flags = 0;
    const double accScale = kStandardGravity / accelLsbPerG_;
    const double gyrScale = kPi / 180.0 / gyroLsbPerDps_;
    setAccelGyro(out, {be16(&b.accel[0]), be16(&b.accel[2]), be16(&b.accel[4])},
                 {be16(&b.gyro[0]), be16(&b.gyro[2]), be16(&b.gyro[4])}, accScale, gyrScale);
    out.temperatureC = static_cast<float>(be16(b.temp) / kTempLsbPerDegC + kTempOffsetDegC);
    if ((b.magSt1 & ak09916::ST1_DRDY) != 0) {
        // The AK09916's axes are the accelerometer's x, -y, -z (datasheet, orientation of axes).
        const double s = ak09916::kMicroteslaPerLsb;
        out.magUt = Eigen::Vector3f(static_cast<float>(le16(&b.mag[0]) * s),
                                    static_cast<float>(-le16(&b.mag[2]) * s),
                                    static_cast<float>(-le16(&b.mag[4]) * s));
        out.flags |= ImuSample::kMagFresh;
        if ((b.magSt2 & ak09916::ST2_HOFL) != 0) {
            out.flags |= ImuSample::kMagOverflow;
        }
    }
    counters_.bump(counters_.samples);
    return 0;
}

}  // namespace caphub::hal
