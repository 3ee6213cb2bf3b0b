#include "firmware/sensor_calibration_steps.h"

#include <fmt/format.h>

#include "fusion/calibration/accel_six_position.h"
#include "fusion/calibration/still_intervals.h"

namespace caphub::firmware {

CalibrationSamples::CalibrationSamples(const board::Board& b)
    : gyr(b.sensors.size()),
      acc(b.sensors.size()),
      mag(b.sensors.size()),
      magAcc(b.sensors.size()) {
    for (const auto& s : b.sensors) {
        rateHz.push_back(s.achievedOdrHz);
    }
}

void CalibrationSamples::add(const SensorSample& s) {
    const auto i = static_cast<std::size_t>(s.sensor);
    if (s.sensor < 0 || i >= gyr.size()) {
        return;
    }
    gyr[i].push_back(s.sample.gyrRadps.cast<double>());
    acc[i].push_back(s.sample.accMps2.cast<double>());
    if ((s.sample.flags & hal::ImuSample::kMagFresh) != 0 &&
        (s.sample.flags & hal::ImuSample::kMagOverflow) == 0) {
        mag[i].push_back(s.sample.magUt.cast<double>());
        magAcc[i].push_back(s.sample.accMps2.cast<double>());
    }
}

void CalibrationSamples::clear() {
    for (auto* v : {&gyr, &acc, &mag, &magAcc}) {
        for (auto& each : *v) {
            each.clear();
        }
    }
}

Result<fusion::GyroBiasResult> calibrateGyroBias(const CalibrationSamples& st, std::size_t i,
                                                 fusion::SensorCalibration& cal) {
    auto r = fusion::estimateGyroBias(st.gyr[i]);
    if (!r) {
        return r.error();
    }
    cal.hasGyro = true;
    cal.gyroBiasRadS = r->biasRadS;
    return *r;
}

Result<AxesResult> calibrateAxes(const CalibrationSamples& st, std::size_t i,
                                 fusion::SensorCalibration& cal) {
    const auto held = fusion::findHeldPositions(st.acc[i], st.gyr[i], st.rateHz[i]);
    if (!held) {
        return held.error();
    }
    std::vector<Vec3d> means;
    for (const auto& h : *held) {
        means.push_back(h.meanAccMps2);
    }
    AxesResult out;
    out.heldPositions = static_cast<int>(means.size());
    if (out.heldPositions >= fusion::AccelAxesParams{}.minPositions) {
        auto a = fusion::calibrateAccelAxes(means);
        if (!a) {
            return a.error();
        }
        out.acc = *a;
        auto g = fusion::calibrateGyroAxes(st.gyr[i], st.rateHz[i], *held, out.acc);
        if (!g) {
            return g.error();
        }
        out.gyro = *g;
    } else {
        auto six = fusion::findSixPositions(st.acc[i], st.gyr[i], st.rateHz[i]);
        if (!six) {
            return Error{six.error().code,
                         fmt::format("{} held positions (nine or more give the axes); {}",
                                     means.size(), six.error().message)};
        }
        auto r = fusion::calibrateAccelSixPosition(*six);
        if (!r) {
            return r.error();
        }
        out.acc.offsetMps2 = r->offsetMps2;
        out.acc.matrix = r->scale.cwiseInverse().asDiagonal();
        out.acc.residualMps2 = r->residualMps2;
        out.acc.positions = 6;
    }
    cal.hasAccel = true;
    cal.accOffsetMps2 = out.acc.offsetMps2;
    cal.accMatrix = out.acc.matrix;
    cal.hasGyroAxes = out.gyro.has_value();
    cal.gyroMatrix = out.gyro ? out.gyro->matrix : Eigen::Matrix3d::Identity();
    return out;
}

Result<MagResult> calibrateMagnetometer(const CalibrationSamples& st, std::size_t i,
                                        fusion::SensorCalibration& cal) {
    auto r = fusion::fitEllipsoid(st.mag[i]);
    if (!r) {
        return r.error();
    }
    MagResult out;
    out.fit = *r;
    if (cal.hasAccel) {
        std::vector<Vec3d> acc;
        std::vector<Vec3d> mag;
        for (std::size_t k = 0; k < st.mag[i].size(); ++k) {
            acc.push_back(cal.accMatrix * (st.magAcc[i][k] - cal.accOffsetMps2));
            mag.push_back(r->softIron * (st.mag[i][k] - r->hardIronUt));
        }
        auto a = fusion::alignMagToAccel(acc, mag);
        if (!a) {
            return a.error();
        }
        out.align = *a;
    }
    cal.hasMag = true;
    cal.magHardIronUt = r->hardIronUt;
    cal.magSoftIron = out.align ? Eigen::Matrix3d(out.align->rotation * r->softIron) : r->softIron;
    cal.magQualityPct = r->qualityPct;
    cal.magCoverage = r->coverage;
    return out;
}

}  // namespace caphub::firmware
