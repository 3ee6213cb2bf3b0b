#include "hal/drivers/lsm6dsox_lis3mdl.h"

#include <cerrno>
#include <cmath>

#include "hal/drivers/lis3mdl_registers.h"
#include "hal/drivers/lsm6dsox_registers.h"

namespace caphub::hal {

namespace {

constexpr std::uint8_t reg(lsm6dsox::Register r) {
    return static_cast<std::uint8_t>(r);
}
constexpr std::uint8_t reg(lis3mdl::Register r) {
    return static_cast<std::uint8_t>(r);
}
constexpr std::uint8_t inverse(std::uint8_t v) {
    return static_cast<std::uint8_t>(~v);
}

// LIS3MDL CTRL_REG1 rate bits for a rate (ultra-high-performance X/Y): DO code, or FAST_ODR.
int lis3mdlRate(double hz, std::uint8_t& bits) {
    using namespace lis3mdl;
    for (int d = 0; d < 8; ++d) {
        if (kDoRateHz[d] == hz) {
            bits = static_cast<std::uint8_t>(omBits(3) | doBits(d));
            return 0;
        }
    }
    for (int om = 0; om < 4; ++om) {
        if (kFastOdrHzByOm[om] == hz) {
            bits = static_cast<std::uint8_t>(omBits(om) | ctrl_reg1::FAST_ODR);
            return 0;
        }
    }
    return -EINVAL;
}

}  // namespace

Lsm6dsoxLis3mdl::Lsm6dsoxLis3mdl(std::unique_ptr<RegisterIo> imu, std::unique_ptr<RegisterIo> mag,
                                 std::string name, const ImuConfig& config)
    : ImuDriver(std::move(name), config), imu_(std::move(imu)), mag_(std::move(mag)) {}

int Lsm6dsoxLis3mdl::odrCode(double hz) {
    for (int c = 1; c <= 10; ++c) {
        if (lsm6dsox::kOdrHz[c] == hz) {
            return c;
        }
    }
    return -1;
}

int Lsm6dsoxLis3mdl::accelFsCode(double g) {
    for (int c = 0; c < 4; ++c) {
        if (lsm6dsox::kAccelRangeByCode[c] == g) {
            return c;
        }
    }
    return -1;
}

int Lsm6dsoxLis3mdl::gyroFsCode(double dps) {
    for (int c = 0; c < 4; ++c) {
        if (lsm6dsox::kGyroRangeByCode[c] == dps) {
            return c;
        }
    }
    return dps == 125 ? 4 : -1;
}

int Lsm6dsoxLis3mdl::readRegister(std::uint8_t space, std::uint8_t r, std::uint8_t& value) {
    return (space == kImuSpace ? *imu_ : *mag_).readByte(r, value);
}

int Lsm6dsoxLis3mdl::writeRegister(std::uint8_t space, std::uint8_t r, std::uint8_t value) {
    return (space == kImuSpace ? *imu_ : *mag_).write(r, value);
}

int Lsm6dsoxLis3mdl::probe() {
    std::uint8_t who = 0;
    if (int r = imu_->readByte(reg(lsm6dsox::Register::WHO_AM_I), who); r < 0) {
        return r;
    }
    if (who != lsm6dsox::kWhoAmI) {
        return -ENODEV;
    }
    if (int r = mag_->readByte(reg(lis3mdl::Register::WHO_AM_I), who); r < 0) {
        return r;
    }
    return who == lis3mdl::kWhoAmI ? 0 : -ENODEV;
}

int Lsm6dsoxLis3mdl::softReset() {
    if (int r = imu_->write(reg(lsm6dsox::Register::CTRL3_C),
                            lsm6dsox::ctrl3_c::kResetValue | lsm6dsox::ctrl3_c::SW_RESET);
        r < 0) {
        return r;
    }
    return mag_->write(reg(lis3mdl::Register::CTRL_REG2), lis3mdl::ctrl_reg2::SOFT_RST);
}

int Lsm6dsoxLis3mdl::buildSettings(SettingTable& t) {
    using namespace lsm6dsox;
    const ImuConfig& c = config();
    const int odr = odrCode(c.odrHz);
    const int afs = accelFsCode(c.accelRangeG);
    const int gfs = gyroFsCode(c.gyroRangeDps);
    std::uint8_t magRate = 0;
    if (odr < 0 || afs < 0 || gfs < 0 || lis3mdlRate(c.magOdrHz, magRate) < 0) {
        return -EINVAL;
    }
    accelMps2PerLsb_ = kAccelMgPerLsbByCode[afs] * 1e-3 * kStandardGravity;
    const double mdps = gfs == 4 ? kGyroMdpsPerLsb125 : kGyroMdpsPerLsbByCode[gfs];
    gyroRadpsPerLsb_ = mdps * 1e-3 * kPi / 180.0;
    magUtPerLsb_ = 100.0 / lis3mdl::kLsbPerGauss[0];  // +-4 gauss: earth field with margin
    magPeriod_ = periodFromHz(c.magOdrHz);

    const std::uint8_t ctrl1 = static_cast<std::uint8_t>(odrBits(odr) | fsBits(afs));
    const std::uint8_t ctrl2 =
        static_cast<std::uint8_t>(odrBits(odr) | (gfs == 4 ? FS_125 : fsBits(gfs)));
    const std::uint8_t int1 = c.dataReadyInterrupt ? INT1_DRDY_G : 0;
    std::size_t n = 0;
    auto add = [&](std::uint8_t space, std::uint8_t r, std::uint8_t set, std::uint8_t clear) {
        t[n++] = RegisterSetting{space, r, set, clear};
    };
    // Block data update (no torn samples), auto-increment; INT active high, push-pull, 4-wire.
    add(kImuSpace, reg(Register::CTRL3_C), ctrl3_c::BDU | ctrl3_c::IF_INC,
        ctrl3_c::BOOT | ctrl3_c::H_LACTIVE | ctrl3_c::PP_OD | ctrl3_c::SIM | ctrl3_c::SW_RESET);
    add(kImuSpace, reg(Register::CTRL1_XL), ctrl1, inverse(ctrl1));
    add(kImuSpace, reg(Register::CTRL2_G), ctrl2, inverse(ctrl2));
    add(kImuSpace, reg(Register::CTRL6_C), 0, XL_HM_MODE);
    add(kImuSpace, reg(Register::CTRL7_G), 0, G_HM_MODE);
    add(kImuSpace, reg(Register::COUNTER_BDR_REG1), DATAREADY_PULSED, 0);
    add(kImuSpace, reg(Register::INT1_CTRL), int1, inverse(int1));

    using namespace lis3mdl;
    const std::uint8_t reg1 = static_cast<std::uint8_t>(ctrl_reg1::TEMP_EN | magRate);
    add(kMagSpace, reg(lis3mdl::Register::CTRL_REG1), reg1, inverse(reg1));
    add(kMagSpace, reg(lis3mdl::Register::CTRL_REG2), lis3mdl::fsBits(0),
        ctrl_reg2::FS_MASK | ctrl_reg2::REBOOT | ctrl_reg2::SOFT_RST);
    add(kMagSpace, reg(lis3mdl::Register::CTRL_REG3), MD_CONTINUOUS, 0xFF);
    add(kMagSpace, reg(lis3mdl::Register::CTRL_REG4), omzBits(3), 0x02);
    add(kMagSpace, reg(lis3mdl::Register::CTRL_REG5), BDU, 0x80);
    return static_cast<int>(n);
}

int Lsm6dsoxLis3mdl::dataReady(bool& ready) {
    std::uint8_t status = 0;
    const int r = imu_->readByte(reg(lsm6dsox::Register::STATUS_REG), status);
    ready = r == 0 && (status & lsm6dsox::GDA) != 0 && (status & lsm6dsox::XLDA) != 0;
    return r;
}

int Lsm6dsoxLis3mdl::readMag(ImuSample& out) {
    std::uint8_t block[7];  // STATUS_REG, OUT_X_L .. OUT_Z_H
    if (int r = mag_->read(reg(lis3mdl::Register::STATUS_REG), block); r < 0) {
        return r;
    }
    if ((block[0] & lis3mdl::ZYXDA) != 0) {
        out.magUt = Eigen::Vector3f(static_cast<float>(le16(&block[1]) * magUtPerLsb_),
                                    static_cast<float>(le16(&block[3]) * magUtPerLsb_),
                                    static_cast<float>(le16(&block[5]) * magUtPerLsb_));
        out.flags |= ImuSample::kMagFresh;
        for (int i = 0; i < 3; ++i) {
            if (atFullScale(le16(&block[1 + 2 * i]))) {
                out.flags |= ImuSample::kMagOverflow;
            }
        }
    }
    return 0;
}

int Lsm6dsoxLis3mdl::readSample(Timestamp t, ImuSample& out) {
    lsm6dsox::SampleBurst b{};
    auto* bytes = reinterpret_cast<std::uint8_t*>(&b);
    if (int r = imu_->read(reg(lsm6dsox::Register::OUT_TEMP_L),
                           std::span<std::uint8_t>(bytes, sizeof b));
        r < 0) {
        counters_.bump(counters_.readErrors);
        return r;
    }
    out.t = t;
    out.flags = 0;
    setAccelGyro(out, {le16(&b.accel[0]), le16(&b.accel[2]), le16(&b.accel[4])},
                 {le16(&b.gyro[0]), le16(&b.gyro[2]), le16(&b.gyro[4])}, accelMps2PerLsb_,
                 gyroRadpsPerLsb_);
    out.temperatureC =
        static_cast<float>(le16(b.temp) / lsm6dsox::kTempLsbPerDegC + lsm6dsox::kTempOffsetDegC);
    // Polled at least twice per magnetometer period, so no magnetometer sample is missed; its
    // status bit tells whether the reading is new.
    if (!lastMagRead_ || t - *lastMagRead_ >= magPeriod_ / 2) {
        lastMagRead_ = t;
        if (int r = readMag(out); r < 0) {
            counters_.bump(counters_.readErrors);
            return r;
        }
    }
    counters_.bump(counters_.samples);
    return 0;
}

}  // namespace caphub::hal
