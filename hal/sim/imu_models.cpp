#include "hal/sim/imu_models.h"

#include <cerrno>
#include <cmath>

#include "hal/drivers/ak09916_registers.h"
#include "hal/drivers/icm20948_registers.h"
#include "hal/drivers/lis3mdl_registers.h"
#include "hal/drivers/lsm6dsox_registers.h"
#include "hal/imu_sample.h"

namespace caphub::hal::sim {

namespace {

void putBe16(std::uint8_t* p, std::int16_t v) {
    const auto u = static_cast<std::uint16_t>(v);
    p[0] = static_cast<std::uint8_t>(u >> 8);
    p[1] = static_cast<std::uint8_t>(u & 0xFF);
}

void putLe16(std::uint8_t* p, std::int16_t v) {
    const auto u = static_cast<std::uint16_t>(v);
    p[0] = static_cast<std::uint8_t>(u & 0xFF);
    p[1] = static_cast<std::uint8_t>(u >> 8);
}

}  // namespace

// ---------------------------------------------------------------- AK09916

void Ak09916Model::reset() {
    regs_.fill(0);
    regs_[static_cast<int>(ak09916::Register::WIA1)] = ak09916::kCompanyId;
    regs_[static_cast<int>(ak09916::Register::WIA2)] = ak09916::kDeviceId;
    latched_ = -1;
    fresh_ = false;
}

Duration Ak09916Model::samplePeriod() const {
    switch (static_cast<ak09916::Mode>(regs_[static_cast<int>(ak09916::Register::CNTL2)])) {
        case ak09916::Mode::Continuous10Hz:
            return periodFromHz(10);
        case ak09916::Mode::Continuous20Hz:
            return periodFromHz(20);
        case ak09916::Mode::Continuous50Hz:
            return periodFromHz(50);
        case ak09916::Mode::Continuous100Hz:
            return periodFromHz(100);
        default:
            return Duration{0};
    }
}

void Ak09916Model::update(Timestamp now) {
    const Duration period = samplePeriod();
    if (period.count() <= 0 || now < epoch_) {
        return;
    }
    const std::int64_t k = (now - epoch_).count() / period.count();
    if (k == latched_ || k < 0) {
        return;
    }
    if (fresh_) {
        regs_[static_cast<int>(ak09916::Register::ST1)] |= ak09916::ST1_DOR;  // overrun
    }
    latched_ = k;
    const Timestamp t = epoch_ + period * k;
    const Eigen::Vector3d field = source_ != nullptr ? source_->at(t).magUt : PhysicalInput{}.magUt;
    // The AK09916's axes are the ICM-20948 accelerometer's x, -y, -z.
    const Eigen::Vector3d inDie(field.x(), -field.y(), -field.z());
    bool overflow = false;
    for (int i = 0; i < 3; ++i) {
        const double counts = std::round(inDie[i] / ak09916::kMicroteslaPerLsb);
        overflow = overflow || std::abs(counts) > ak09916::kMaxCounts;
        const double clamped =
            std::clamp(counts, -double(ak09916::kMaxCounts), double(ak09916::kMaxCounts));
        putLe16(&regs_[static_cast<std::size_t>(0x11 + 2 * i)], static_cast<std::int16_t>(clamped));
    }
    regs_[static_cast<int>(ak09916::Register::ST2)] = overflow ? ak09916::ST2_HOFL : 0;
    regs_[static_cast<int>(ak09916::Register::ST1)] |= ak09916::ST1_DRDY;
    fresh_ = true;
}

std::uint8_t Ak09916Model::read(Timestamp now, std::uint8_t reg) {
    if (reg >= regs_.size()) {
        return 0;
    }
    update(now);
    const std::uint8_t v = regs_[reg];
    if (reg == static_cast<int>(ak09916::Register::ST2)) {
        // Reading ST2 ends the read-out: data-ready and overrun clear.
        regs_[static_cast<int>(ak09916::Register::ST1)] = 0;
        fresh_ = false;
    }
    return v;
}

void Ak09916Model::write(Timestamp now, std::uint8_t reg, std::uint8_t value) {
    if (reg == static_cast<int>(ak09916::Register::CNTL3)) {
        if ((value & ak09916::CNTL3_SRST) != 0) {
            reset();
        }
        return;
    }
    if (reg == static_cast<int>(ak09916::Register::CNTL2)) {
        regs_[reg] = static_cast<std::uint8_t>(value & 0x1F);
        epoch_ = now;
        latched_ = -1;
    }
}

// ---------------------------------------------------------------- ICM-20948

void Icm20948Model::resetToDefaults() {
    using namespace icm20948;
    for (auto& bank : regs_) {
        bank.fill(0);
    }
    regs_[0][static_cast<int>(Bank0::WHO_AM_I)] = kWhoAmI;
    regs_[0][static_cast<int>(Bank0::LP_CONFIG)] = 0x40;
    regs_[0][static_cast<int>(Bank0::PWR_MGMT_1)] = pwr_mgmt_1::kResetValue;
    regs_[2][static_cast<int>(Bank2::GYRO_CONFIG_1)] = 0x01;
    regs_[2][static_cast<int>(Bank2::ACCEL_CONFIG)] = 0x01;
    bank_ = 0;
    mag_.reset();
}

Duration Icm20948Model::samplePeriod() const {
    using namespace icm20948;
    if ((regs_[0][static_cast<int>(Bank0::PWR_MGMT_1)] & pwr_mgmt_1::SLEEP) != 0) {
        return Duration{0};
    }
    const int div = regs_[2][static_cast<int>(Bank2::GYRO_SMPLRT_DIV)];
    return periodFromHz(kGyroBaseRateHz / (1 + div));
}

bool Icm20948Model::dataReadyEnabled() const {
    using namespace icm20948;
    return (regs_[0][static_cast<int>(Bank0::INT_ENABLE_1)] & RAW_DATA_0_RDY) != 0 &&
           samplePeriod().count() > 0;
}

std::uint8_t Icm20948Model::readRegister(Timestamp, std::uint8_t reg) {
    using namespace icm20948;
    reg &= 0x7F;
    if (reg == kRegBankSel) {
        return bankSelValue(bank_);
    }
    auto& r = regs_[static_cast<std::size_t>(bank_)][reg];
    const std::uint8_t v = r;
    if (bank_ == 0 && (reg == static_cast<int>(Bank0::INT_STATUS_1) ||
                       reg == static_cast<int>(Bank0::I2C_MST_STATUS))) {
        r = 0;  // cleared by reading
    }
    return v;
}

void Icm20948Model::writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) {
    using namespace icm20948;
    reg &= 0x7F;
    if (reg == kRegBankSel) {
        bank_ = (value >> 4) & 3;
        return;
    }
    if (bank_ == 0) {
        switch (static_cast<Bank0>(reg)) {
            case Bank0::WHO_AM_I:
            case Bank0::INT_STATUS:
            case Bank0::INT_STATUS_1:
            case Bank0::I2C_MST_STATUS:
                return;  // read-only
            case Bank0::PWR_MGMT_1: {
                if ((value & pwr_mgmt_1::DEVICE_RESET) != 0) {
                    resetToDefaults();
                    return;
                }
                const bool wasAsleep = samplePeriod().count() == 0;
                regs_[0][reg] = value;
                if (wasAsleep && samplePeriod().count() > 0) {
                    restartSchedule(now);
                }
                return;
            }
            default:
                break;
        }
        if (reg >= static_cast<int>(Bank0::ACCEL_XOUT_H) && reg < 0x53) {
            return;  // data registers are read-only
        }
    }
    regs_[static_cast<std::size_t>(bank_)][reg] = value;
    if (bank_ == 2 && reg == static_cast<int>(Bank2::GYRO_SMPLRT_DIV)) {
        restartSchedule(now);
    }
    if (bank_ == 3 && reg == static_cast<int>(Bank3::I2C_SLV4_CTRL) &&
        (value & slv_ctrl::EN) != 0) {
        auxSlave4(now);
    }
}

void Icm20948Model::auxSlave4(Timestamp now) {
    using namespace icm20948;
    auto& b3 = regs_[3];
    b3[static_cast<int>(Bank3::I2C_SLV4_CTRL)] &= static_cast<std::uint8_t>(~slv_ctrl::EN);
    if ((regs_[0][static_cast<int>(Bank0::USER_CTRL)] & user_ctrl::I2C_MST_EN) == 0) {
        return;  // the master is off: the transaction never completes
    }
    const std::uint8_t addr = b3[static_cast<int>(Bank3::I2C_SLV4_ADDR)];
    const std::uint8_t reg = b3[static_cast<int>(Bank3::I2C_SLV4_REG)];
    auto& status = regs_[0][static_cast<int>(Bank0::I2C_MST_STATUS)];
    if ((addr & 0x7F) != ak09916::kI2cAddress) {
        status |= I2C_SLV4_NACK | I2C_SLV4_DONE;
        return;
    }
    if ((addr & I2C_SLV_RNW) != 0) {
        b3[static_cast<int>(Bank3::I2C_SLV4_DI)] = mag_.read(now, reg);
    } else {
        mag_.write(now, reg, b3[static_cast<int>(Bank3::I2C_SLV4_DO)]);
    }
    status |= I2C_SLV4_DONE;
}

void Icm20948Model::latchSample(Timestamp t, const PhysicalInput& in) {
    using namespace icm20948;
    auto& b0 = regs_[0];
    const int gyroFs = (regs_[2][static_cast<int>(Bank2::GYRO_CONFIG_1)] >> 1) & 3;
    const int accelFs = (regs_[2][static_cast<int>(Bank2::ACCEL_CONFIG)] >> 1) & 3;
    const double accLsb = kAccelLsbPerG[accelFs] / kStandardGravity;
    const double gyrLsb = kGyroLsbPerDps[gyroFs] * kRadToDeg;
    for (int i = 0; i < 3; ++i) {
        putBe16(&b0[static_cast<std::size_t>(0x2D + 2 * i)], quantise(in.accMps2[i], accLsb));
        putBe16(&b0[static_cast<std::size_t>(0x33 + 2 * i)], quantise(in.gyrRadps[i], gyrLsb));
    }
    putBe16(&b0[0x39], quantise(in.temperatureC - kTempOffsetDegC, kTempLsbPerDegC));
    b0[static_cast<int>(Bank0::INT_STATUS_1)] |= RAW_DATA_0_RDY;

    // The auxiliary master's slave 0 copies its block from the AK09916.
    const auto& b3 = regs_[3];
    const std::uint8_t ctrl = b3[static_cast<int>(Bank3::I2C_SLV0_CTRL)];
    const std::uint8_t addr = b3[static_cast<int>(Bank3::I2C_SLV0_ADDR)];
    if ((b0[static_cast<int>(Bank0::USER_CTRL)] & user_ctrl::I2C_MST_EN) != 0 &&
        (ctrl & slv_ctrl::EN) != 0 && (addr & I2C_SLV_RNW) != 0 &&
        (addr & 0x7F) == ak09916::kI2cAddress) {
        const int len = ctrl & slv_ctrl::LENG_MASK;
        const std::uint8_t reg = b3[static_cast<int>(Bank3::I2C_SLV0_REG)];
        for (int i = 0; i < len; ++i) {
            b0[static_cast<std::size_t>(0x3B + i)] =
                mag_.read(t, static_cast<std::uint8_t>(reg + i));
        }
    }
}

// ---------------------------------------------------------------- LSM6DSOX

void Lsm6dsoxModel::resetToDefaults() {
    using namespace lsm6dsox;
    regs_.fill(0);
    regs_[static_cast<int>(Register::WHO_AM_I)] = kWhoAmI;
    regs_[static_cast<int>(Register::CTRL3_C)] = ctrl3_c::kResetValue;
}

Duration Lsm6dsoxModel::samplePeriod() const {
    using namespace lsm6dsox;
    int code = regs_[static_cast<int>(Register::CTRL2_G)] >> 4;
    if (code == 0) {
        code = regs_[static_cast<int>(Register::CTRL1_XL)] >> 4;
    }
    if (code < 1 || code > 10) {
        return Duration{0};
    }
    return periodFromHz(kOdrHz[code]);
}

bool Lsm6dsoxModel::dataReadyEnabled() const {
    using namespace lsm6dsox;
    return (regs_[static_cast<int>(Register::INT1_CTRL)] & (INT1_DRDY_G | INT1_DRDY_XL)) != 0 &&
           samplePeriod().count() > 0;
}

bool Lsm6dsoxModel::autoIncrement(std::uint8_t) const {
    return (regs_[static_cast<int>(lsm6dsox::Register::CTRL3_C)] & lsm6dsox::ctrl3_c::IF_INC) != 0;
}

void Lsm6dsoxModel::decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const {
    read = (cmd & 0x80) != 0;
    reg = static_cast<std::uint8_t>(cmd & 0x7F);
    inc = autoIncrement(cmd);
}

std::uint8_t Lsm6dsoxModel::readRegister(Timestamp, std::uint8_t reg) {
    using namespace lsm6dsox;
    reg &= 0x7F;
    const std::uint8_t v = regs_[reg];
    auto& status = regs_[static_cast<int>(Register::STATUS_REG)];
    if (reg == 0x27) {
        status &= static_cast<std::uint8_t>(~GDA);  // OUTZ_H_G read
    } else if (reg == static_cast<int>(Register::OUTZ_H_A)) {
        status &= static_cast<std::uint8_t>(~XLDA);
    } else if (reg == 0x21) {
        status &= static_cast<std::uint8_t>(~TDA);
    }
    return v;
}

void Lsm6dsoxModel::writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) {
    using namespace lsm6dsox;
    reg &= 0x7F;
    if (reg == static_cast<int>(Register::WHO_AM_I) ||
        reg == static_cast<int>(Register::STATUS_REG) ||
        (reg >= static_cast<int>(Register::OUT_TEMP_L) &&
         reg <= static_cast<int>(Register::OUTZ_H_A))) {
        return;  // read-only
    }
    if (reg == static_cast<int>(Register::CTRL3_C) &&
        (value & (ctrl3_c::SW_RESET | ctrl3_c::BOOT)) != 0) {
        resetToDefaults();
        return;
    }
    const Duration before = samplePeriod();
    regs_[reg] = value;
    if (samplePeriod() != before) {
        restartSchedule(now);
    }
}

void Lsm6dsoxModel::latchSample(Timestamp, const PhysicalInput& in) {
    using namespace lsm6dsox;
    const std::uint8_t ctrl1 = regs_[static_cast<int>(Register::CTRL1_XL)];
    const std::uint8_t ctrl2 = regs_[static_cast<int>(Register::CTRL2_G)];
    const double accLsb = 1.0 / (kAccelMgPerLsbByCode[(ctrl1 >> 2) & 3] * 1e-3 * kStandardGravity);
    const double mdps =
        (ctrl2 & FS_125) != 0 ? kGyroMdpsPerLsb125 : kGyroMdpsPerLsbByCode[(ctrl2 >> 2) & 3];
    const double gyrLsb = kRadToDeg / (mdps * 1e-3);
    putLe16(&regs_[0x20], quantise(in.temperatureC - kTempOffsetDegC, kTempLsbPerDegC));
    for (int i = 0; i < 3; ++i) {
        putLe16(&regs_[static_cast<std::size_t>(0x22 + 2 * i)], quantise(in.gyrRadps[i], gyrLsb));
        putLe16(&regs_[static_cast<std::size_t>(0x28 + 2 * i)], quantise(in.accMps2[i], accLsb));
    }
    regs_[static_cast<int>(Register::STATUS_REG)] |= XLDA | GDA | TDA;
}

// ---------------------------------------------------------------- LIS3MDL

void Lis3mdlModel::resetToDefaults() {
    using namespace lis3mdl;
    regs_.fill(0);
    regs_[static_cast<int>(Register::WHO_AM_I)] = kWhoAmI;
    regs_[static_cast<int>(Register::CTRL_REG1)] = 0x10;  // 10 Hz, low-power
    regs_[static_cast<int>(Register::CTRL_REG3)] = kCtrlReg3ResetValue;
}

Duration Lis3mdlModel::samplePeriod() const {
    using namespace lis3mdl;
    if ((regs_[static_cast<int>(Register::CTRL_REG3)] & MD_MASK) != MD_CONTINUOUS) {
        return Duration{0};
    }
    const std::uint8_t r1 = regs_[static_cast<int>(Register::CTRL_REG1)];
    const double hz =
        (r1 & ctrl_reg1::FAST_ODR) != 0 ? kFastOdrHzByOm[(r1 >> 5) & 3] : kDoRateHz[(r1 >> 2) & 7];
    return periodFromHz(hz);
}

void Lis3mdlModel::decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const {
    read = (cmd & lis3mdl::kSpiRead) != 0;
    inc = (cmd & lis3mdl::kSpiAutoIncrement) != 0;
    reg = static_cast<std::uint8_t>(cmd & 0x3F);
}

std::uint8_t Lis3mdlModel::readRegister(Timestamp, std::uint8_t reg) {
    using namespace lis3mdl;
    reg &= 0x3F;
    const std::uint8_t v = regs_[reg];
    if (reg == static_cast<int>(Register::OUT_Z_H)) {
        regs_[static_cast<int>(Register::STATUS_REG)] = 0;
    }
    return v;
}

void Lis3mdlModel::writeRegister(Timestamp now, std::uint8_t reg, std::uint8_t value) {
    using namespace lis3mdl;
    reg &= 0x3F;
    if (reg < static_cast<int>(Register::CTRL_REG1) ||
        reg > static_cast<int>(Register::CTRL_REG5)) {
        return;  // only the control registers are writable
    }
    if (reg == static_cast<int>(Register::CTRL_REG2) &&
        (value & (ctrl_reg2::SOFT_RST | ctrl_reg2::REBOOT)) != 0) {
        resetToDefaults();
        return;
    }
    const Duration before = samplePeriod();
    regs_[reg] = value;
    if (samplePeriod() != before) {
        restartSchedule(now);
    }
}

void Lis3mdlModel::latchSample(Timestamp, const PhysicalInput& in) {
    using namespace lis3mdl;
    const int fs = (regs_[static_cast<int>(Register::CTRL_REG2)] >> 5) & 3;
    const double lsbPerUt = kLsbPerGauss[fs] / 100.0;
    auto& status = regs_[static_cast<int>(Register::STATUS_REG)];
    if ((status & ZYXDA) != 0) {
        status |= ZYXOR;
    }
    for (int i = 0; i < 3; ++i) {
        putLe16(&regs_[static_cast<std::size_t>(0x28 + 2 * i)], quantise(in.magUt[i], lsbPerUt));
    }
    putLe16(&regs_[0x2E], quantise(in.temperatureC - 25.0, 8.0));
    status |= ZYXDA;
}

// ---------------------------------------------------------------- TCA9548A

int Tca9548aModel::i2cWrite(Timestamp, std::span<const std::uint8_t> bytes) {
    if (!bytes.empty()) {
        control_ = bytes.back();
        ++writes_;
    }
    return 0;
}

int Tca9548aModel::i2cRead(Timestamp, std::span<std::uint8_t> out) {
    for (auto& b : out) {
        b = control_;
    }
    return 0;
}

}  // namespace caphub::hal::sim
