#include "firmware/serve/calibration_motion.h"

namespace caphub::firmware::serve {

namespace bs = board::sim;
namespace hs = hal::sim;

namespace {

using ActiveSlot = std::atomic<std::shared_ptr<CalibrationMotion::Active>>;

// A sensor's source: the script's while one is on and has started, else the clip's.
class SwitchedSource final : public hs::PhysicalSource {
public:
    SwitchedSource(std::unique_ptr<hs::PhysicalSource> inner, std::shared_ptr<ActiveSlot> active,
                   std::size_t index)
        : inner_(std::move(inner)), active_(std::move(active)), index_(index) {}

    hs::PhysicalInput at(Timestamp t) override {
        const auto a = active_->load(std::memory_order_acquire);
        if (a && t >= a->start && index_ < a->sources.size() && a->sources[index_]) {
            return a->sources[index_]->at(t);
        }
        return inner_ ? inner_->at(t) : hs::PhysicalInput{};
    }

private:
    std::unique_ptr<hs::PhysicalSource> inner_;
    std::shared_ptr<ActiveSlot> active_;
    std::size_t index_;
};

}  // namespace

CalibrationMotion::CalibrationMotion(const board::Board& board, bs::ErrorProfile profile,
                                     std::uint64_t seed)
    : board_(board), profile_(profile), seed_(seed), active_(std::make_shared<ActiveSlot>()) {}

bs::SourceFactory CalibrationMotion::wrap(bs::SourceFactory inner) {
    return
        [inner = std::move(inner), active = active_](
            const board::SensorConfig& sensor, int index) -> std::unique_ptr<hs::PhysicalSource> {
            return std::make_unique<SwitchedSource>(inner ? inner(sensor, index) : nullptr, active,
                                                    static_cast<std::size_t>(index));
        };
}

void CalibrationMotion::play(bs::Script script, const bs::ScriptTiming& timing, Timestamp start) {
    bs::ScriptOptions so;
    so.script = script;
    so.timing = timing;
    so.profile = profile_;
    so.seed = seed_;
    const bs::ScriptedSuit suit = bs::scriptedSources(so, start);
    auto a = std::make_shared<Active>();
    a->start = start;
    for (std::size_t i = 0; i < board_.sensors.size(); ++i) {
        a->sources.push_back(suit.sources(board_.sensors[i], static_cast<int>(i)));
    }
    active_->store(std::move(a), std::memory_order_release);
}

void CalibrationMotion::stop() {
    active_->store(nullptr, std::memory_order_release);
}

}  // namespace caphub::firmware::serve
