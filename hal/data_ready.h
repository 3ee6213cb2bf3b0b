// The data-ready seam: a sensor's data-ready line (a GPIO rising edge stamped by the kernel), or
// a timer at the sensor's rate when no line is wired, and a waiter that sleeps on the lines of
// one bus worker together. 0 or -errno, no logging.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "hal/core/time.h"

namespace caphub::hal {

class DataReadyLine {
public:
    virtual ~DataReadyLine() = default;

    // Waits for the next edge and returns its time: 0, -ETIMEDOUT, or -errno.
    [[nodiscard]] virtual int waitEdge(Duration timeout, Timestamp& edgeTime) = 0;

    // Takes one pending edge without blocking: 0, -EAGAIN when none is pending, or -errno.
    [[nodiscard]] virtual int readEdge(Timestamp& edgeTime) = 0;

    // True for a timer standing in for a missing line: the driver must check the chip's
    // data-ready status bit before reading.
    virtual bool isTimer() const = 0;

    virtual std::string name() const = 0;
};

// Waits on several lines at once (one bus worker's). Lines are identified by their index in the
// order they were added.
class DataReadyWaiter {
public:
    virtual ~DataReadyWaiter() = default;

    [[nodiscard]] virtual int add(DataReadyLine& line) = 0;

    // Waits until at least one line has a pending edge or the timeout passes. Writes the indices
    // of the ready lines into ready and returns their count (0 on timeout), or -errno. The edges
    // themselves are then taken with each line's readEdge().
    [[nodiscard]] virtual int wait(Duration timeout, std::span<int> ready) = 0;
};

}  // namespace caphub::hal
