// Bus budget: what the sensors of a board cost each bus per second at their configured rates,
// on the wire (address, register and data bytes, start/stop and ACK bits at the bus clock).
// The loader refuses a plan above kMaxBusUtilisation: the rest is the margin for driver and
// scheduling gaps between transactions, which wire time does not count.
#pragma once

#include <vector>

#include "board/board.h"

namespace caphub::board {

inline constexpr double kMaxBusUtilisation = 0.80;

struct SensorLoad {
    int sensor = -1;
    double transactionsPerS = 0;
    double bytesPerS = 0;
    double utilisation = 0;  // fraction of the bus's time
};

struct BusLoad {
    int bus = -1;
    double transactionsPerS = 0;
    double bytesPerS = 0;
    double utilisation = 0;  // fraction of the bus's time, 0..1 (can exceed 1 for a bad plan)
    double muxSelectsPerS = 0;
    std::vector<SensorLoad> sensors;
};

// Bits on the wire of one transaction.
// I2C register read: S, address+W, register, Sr, address+R, data..., P (each byte 8 bits + ACK).
double i2cRegisterReadBits(int dataBytes);
// I2C write of data bytes with no register (a mux control write): S, address+W, data..., P.
double i2cWriteBits(int dataBytes);
// SPI register read: one command byte then the data bytes, full duplex.
double spiRegisterReadBits(int dataBytes);

// The load of every bus of the board, in the order of Board::buses.
std::vector<BusLoad> computeBusLoads(const Board& board);

}  // namespace caphub::board
