#include "board/bus_budget.h"

#include <algorithm>
#include <map>
#include <set>
#include <utility>

namespace caphub::board {

double i2cRegisterReadBits(int dataBytes) {
    return 1 + 9 + 9 + 1 + 9 + 9.0 * dataBytes + 1;
}

double i2cWriteBits(int dataBytes) {
    return 1 + 9 + 9.0 * dataBytes + 1;
}

double spiRegisterReadBits(int dataBytes) {
    return 8.0 * (1 + dataBytes);
}

namespace {

struct Cost {
    double transactions = 0;
    double bytes = 0;
    double bits = 0;
};

Cost readCost(hal::BusProtocol protocol, const hal::ReadCost& rc, double ratePerS) {
    Cost c;
    if (rc.transactions == 0 || ratePerS <= 0) {
        return c;
    }
    const double perSecond = rc.transactions * ratePerS;
    c.transactions = perSecond;
    if (protocol == hal::BusProtocol::I2c) {
        c.bytes = perSecond * (3 + rc.dataBytes);
        c.bits = perSecond * i2cRegisterReadBits(rc.dataBytes);
    } else {
        c.bytes = perSecond * (1 + rc.dataBytes);
        c.bits = perSecond * spiRegisterReadBits(rc.dataBytes);
    }
    return c;
}

}  // namespace

std::vector<BusLoad> computeBusLoads(const Board& board) {
    std::vector<BusLoad> loads;
    for (std::size_t b = 0; b < board.buses.size(); ++b) {
        const BusConfig& bus = board.buses[b];
        BusLoad load;
        load.bus = static_cast<int>(b);
        double bits = 0;

        // The worker visits the sensors of one (mux, channel) group together; switching between
        // groups costs a channel select (two writes when another mux must be closed first).
        std::map<std::pair<int, int>, double> groupRate;
        std::set<int> muxesUsed;
        for (std::size_t s = 0; s < board.sensors.size(); ++s) {
            const SensorConfig& sensor = board.sensors[s];
            if (sensor.bus != load.bus || sensor.chip == nullptr) {
                continue;
            }
            const hal::ChipInfo& chip = *sensor.chip;
            Cost c = readCost(bus.protocol, chip.imuRead, sensor.achievedOdrHz);
            // A magnetometer read on its own is polled at twice its rate (at most every sample).
            const Cost mag = readCost(bus.protocol, chip.magRead,
                                      std::min(sensor.achievedOdrHz, 2 * sensor.magOdrHz));
            c.transactions += mag.transactions;
            c.bytes += mag.bytes;
            c.bits += mag.bits;
            if (!sensor.dataReady) {
                const Cost poll = readCost(bus.protocol, chip.statusPoll, sensor.achievedOdrHz);
                c.transactions += poll.transactions;
                c.bytes += poll.bytes;
                c.bits += poll.bits;
            }
            SensorLoad sl;
            sl.sensor = static_cast<int>(s);
            sl.transactionsPerS = c.transactions;
            sl.bytesPerS = c.bytes;
            sl.utilisation = c.bits / bus.clockHz;
            load.sensors.push_back(sl);
            load.transactionsPerS += c.transactions;
            load.bytesPerS += c.bytes;
            bits += c.bits;

            auto& rate = groupRate[{sensor.mux, sensor.channel}];
            rate = std::max(rate, sensor.achievedOdrHz);
            if (sensor.mux >= 0) {
                muxesUsed.insert(sensor.mux);
            }
        }
        if (bus.protocol == hal::BusProtocol::I2c && !muxesUsed.empty() && groupRate.size() > 1) {
            const int writesPerSelect = muxesUsed.size() > 1 ? 2 : 1;
            for (const auto& [group, rate] : groupRate) {
                if (group.first < 0) {
                    continue;  // sensors on the bus itself need no select
                }
                const double selects = rate * writesPerSelect;
                load.muxSelectsPerS += rate;
                load.transactionsPerS += selects;
                load.bytesPerS += selects * 2;
                bits += selects * i2cWriteBits(1);
            }
        }
        load.utilisation = bus.clockHz > 0 ? bits / bus.clockHz : 0;
        loads.push_back(std::move(load));
    }
    return loads;
}

}  // namespace caphub::board
