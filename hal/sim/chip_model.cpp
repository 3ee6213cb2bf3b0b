#include "hal/sim/chip_model.h"

#include <cerrno>
#include <cmath>
#include <limits>

namespace caphub::hal::sim {

std::int16_t quantise(double value, double lsbPerUnit) {
    const double counts = std::round(value * lsbPerUnit);
    if (!(counts < std::numeric_limits<std::int16_t>::max())) {
        return std::numeric_limits<std::int16_t>::max();
    }
    if (!(counts > std::numeric_limits<std::int16_t>::min())) {
        return std::numeric_limits<std::int16_t>::min();
    }
    return static_cast<std::int16_t>(counts);
}

bool ChipModel::nacking(Timestamp now) {
    if (now < nackUntil_) {
        ++faults_.nacks;
        return true;
    }
    return false;
}

std::uint8_t ChipModel::maybeCorrupt(std::uint8_t v) {
    if (corruptReads_ > 0) {
        --corruptReads_;
        ++faults_.corruptedBytes;
        return static_cast<std::uint8_t>(v ^ 0x10);
    }
    return v;
}

void ChipModel::update(Timestamp now) {
    const Duration period = samplePeriod();
    if (period.count() <= 0 || now < epoch_) {
        return;
    }
    const std::int64_t k = (now - epoch_).count() / period.count();
    if (k != latched_) {
        latched_ = k;
        const Timestamp t = epoch_ + period * k;
        latchSample(t, (source_ != nullptr ? source_ : &defaultSource_)->at(t));
    }
}

std::optional<Timestamp> ChipModel::nextDataReady(Timestamp after) const {
    const Duration period = samplePeriod();
    if (dataReadyStuck_ || !dataReadyEnabled() || period.count() <= 0) {
        return std::nullopt;
    }
    if (after < epoch_) {
        return epoch_;
    }
    const std::int64_t k = (after - epoch_).count() / period.count() + 1;
    return epoch_ + period * k;
}

int ChipModel::i2cWrite(Timestamp now, std::span<const std::uint8_t> bytes) {
    if (nacking(now)) {
        return -ENXIO;
    }
    if (bytes.empty()) {
        return 0;
    }
    update(now);
    pointer_ = decodeI2cRegister(bytes[0]);
    pointerIncrements_ = autoIncrement(bytes[0]);
    for (std::size_t i = 1; i < bytes.size(); ++i) {
        writeRegister(now, pointer_, bytes[i]);
        if (pointerIncrements_) {
            ++pointer_;
        }
    }
    return 0;
}

int ChipModel::i2cRead(Timestamp now, std::span<std::uint8_t> out) {
    if (nacking(now)) {
        return -ENXIO;
    }
    update(now);
    for (auto& b : out) {
        b = maybeCorrupt(readRegister(now, pointer_));
        if (pointerIncrements_) {
            ++pointer_;
        }
    }
    return 0;
}

void ChipModel::decodeSpi(std::uint8_t cmd, bool& read, std::uint8_t& reg, bool& inc) const {
    read = (cmd & 0x80) != 0;
    reg = static_cast<std::uint8_t>(cmd & 0x7F);
    inc = true;
}

int ChipModel::spiTransfer(Timestamp now, std::span<const std::uint8_t> tx,
                           std::span<std::uint8_t> rx) {
    if (tx.empty() || rx.size() != tx.size()) {
        return -EINVAL;
    }
    if (nacking(now)) {
        // SPI has no acknowledge: a dead chip reads as a floating line.
        for (auto& b : rx) {
            b = 0xFF;
        }
        return 0;
    }
    update(now);
    bool isRead = false;
    bool inc = true;
    std::uint8_t reg = 0;
    decodeSpi(tx[0], isRead, reg, inc);
    rx[0] = 0;
    for (std::size_t i = 1; i < tx.size(); ++i) {
        if (isRead) {
            rx[i] = maybeCorrupt(readRegister(now, reg));
        } else {
            writeRegister(now, reg, tx[i]);
            rx[i] = 0;
        }
        if (inc) {
            ++reg;
        }
    }
    return 0;
}

}  // namespace caphub::hal::sim
