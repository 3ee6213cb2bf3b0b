#include "firmware/runtime/bus_worker.h"

#include <algorithm>
#include <array>
#include <cerrno>

namespace caphub::firmware {

BusWorker::BusWorker(board::BusHardware& hardware, Clock& clock, const Options& options)
    : hw_(hardware), clock_(clock), options_(options), state_(hardware.sensors.size()) {
    for (std::size_t i = 0; i < hw_.sensors.size(); ++i) {
        counters_.push_back(std::make_unique<SensorCounters>());
        const double odr = hw_.sensors[i].driver->config().odrHz;
        state_[i].period = periodFromHz(odr > 0 ? odr : 100);
    }
}

BusWorker::~BusWorker() {
    stop();
}

void BusWorker::emit(RuntimeEvent::Kind kind, std::size_t i, Timestamp t, int error) {
    // Events are rare; a full event ring means nobody reads them, and the counters still tell.
    (void)events_.push(RuntimeEvent{kind, hw_.sensors[i].sensor, t, error});
    produced_ = true;
}

void BusWorker::goOffline(std::size_t i, Timestamp now, int error, RuntimeEvent::Kind kind) {
    SensorState& st = state_[i];
    SensorCounters& c = *counters_[i];
    st.consecutiveErrors = 0;
    if (st.wasOnline) {
        st.wasOnline = false;
        c.online.store(false, std::memory_order_relaxed);
        c.lost.fetch_add(1, std::memory_order_relaxed);
        emit(kind, i, now, error);
    }
    hw_.sensors[i].driver->restart(now);
}

void BusWorker::handleEdge(std::size_t i, Timestamp edge) {
    board::SensorHardware& s = hw_.sensors[i];
    SensorState& st = state_[i];
    SensorCounters& c = *counters_[i];
    st.lastEdge = edge;
    if (s.driver->state() != hal::ImuDriver::State::Running) {
        return;
    }
    if (s.line->isTimer()) {
        bool ready = false;
        if (s.driver->dataReady(ready) == 0 && !ready) {
            return;  // the timer ran ahead of the chip; the next tick takes it
        }
    }
    SensorSample out;
    out.sensor = s.sensor;
    const int r = s.driver->readSample(edge, out.sample);
    if (r < 0) {
        c.readErrors.fetch_add(1, std::memory_order_relaxed);
        if (++st.consecutiveErrors >= options_.lostAfterErrors) {
            goOffline(i, clock_.now(), r, RuntimeEvent::Kind::SensorLost);
        }
        return;
    }
    st.consecutiveErrors = 0;
    c.samples.fetch_add(1, std::memory_order_relaxed);
    if (!samples_.push(out)) {
        c.dropped.fetch_add(1, std::memory_order_relaxed);
    } else {
        produced_ = true;
    }
}

void BusWorker::runOnce() {
    Timestamp now = clock_.now();
    Duration wait = options_.maxWait;
    for (std::size_t i = 0; i < hw_.sensors.size(); ++i) {
        board::SensorHardware& s = hw_.sensors[i];
        SensorState& st = state_[i];
        if (s.driver->state() != hal::ImuDriver::State::Running) {
            const int r = s.driver->service(now);
            if (r == 0) {
                // Edges from before the configuration was complete carry samples taken with the
                // old settings (full scale, rate): drop them, as the driver's FIFO reset would.
                // Those from before now only: a line whose edges come faster than they can be
                // read (a virtual suit paced far beyond the machine) would never run dry.
                Timestamp stale{};
                for (int k = 0; k < kMaxStaleEdges && s.line->readEdge(stale) == 0 && stale <= now;
                     ++k) {
                }
                st.wasOnline = true;
                st.lastEdge = now;
                st.nextCheck = now + options_.checkInterval;
                counters_[i]->online.store(true, std::memory_order_relaxed);
                emit(RuntimeEvent::Kind::SensorOnline, i, now, 0);
            } else {
                wait = std::min(wait, std::max(Duration{0}, s.driver->nextServiceTime() - now));
            }
            continue;
        }
        if (now >= st.nextCheck) {
            st.nextCheck = now + options_.checkInterval;
            const int r = s.driver->checkNextSetting(now);
            if (r == 1) {
                st.wasOnline = false;
                counters_[i]->online.store(false, std::memory_order_relaxed);
                emit(RuntimeEvent::Kind::SensorReset, i, now, 0);
                continue;
            }
        }
        if (now - st.lastEdge > st.period * options_.silentAfterPeriods) {
            goOffline(i, now, -ETIMEDOUT, RuntimeEvent::Kind::LineSilent);
        }
    }

    std::array<int, 32> ready{};
    const int n = hw_.waiter->wait(wait, ready);
    for (int k = 0; k < n; ++k) {
        const auto i = static_cast<std::size_t>(ready[static_cast<std::size_t>(k)]);
        Timestamp edge{};
        // Take the pending edges: a worker that fell behind catches up sample by sample, a
        // bounded number per pass (the chips keep the rest latched, or the line's queue drops
        // the oldest, as the kernel's does).
        for (int taken = 0; taken < kMaxEdgesPerPass && hw_.sensors[i].line->readEdge(edge) == 0;
             ++taken) {
            handleEdge(i, edge);
        }
    }
    if (produced_) {
        produced_ = false;
        if (wake_ != nullptr) {
            wake_->notify();
        }
    }
}

void BusWorker::start(const ThreadPolicy& policy) {
    if (running_.exchange(true)) {
        return;
    }
    thread_ = std::thread([this, policy] {
        (void)applyToThisThread(policy, "caphub-bus");
        while (running_.load(std::memory_order_relaxed)) {
            runOnce();
        }
        cpuNs_.store(thisThreadCpuTime().count(), std::memory_order_relaxed);
    });
}

void BusWorker::stop() {
    if (running_.exchange(false) || thread_.joinable()) {
        // A worker asleep on a simulated clock paced far below real time would sleep on for
        // seconds (one sample period can be minutes at --speed 0.001).
        clock_.interrupt();
    }
    if (thread_.joinable()) {
        thread_.join();
    }
}

}  // namespace caphub::firmware
