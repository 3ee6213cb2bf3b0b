// A board (suit) definition: the buses of the hub, the muxes on them, the sensors with their
// body segments, the display, the outputs and the subject. Loaded from TOML by board/loader.h;
// the format is documented in docs/board-format.md.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "board/body_layout.h"
#include "board/segment.h"
#include "board/subject.h"
#include "hal/chip_info.h"
#include "hal/core/quaternion.h"

namespace caphub::board {

struct SourceLocation {
    std::string file;
    int line = 0;
    int column = 0;
};

enum class BusType { I2c, Spi, Sim };

struct BusConfig {
    std::string name;
    BusType type = BusType::Sim;
    hal::BusProtocol protocol = hal::BusProtocol::I2c;  // what a sim bus models
    std::string device;                                 // /dev/i2c-N or /dev/spidevB; empty on sim
    double clockHz = 400e3;
    SourceLocation where;
};

// A TCA9548A I2C switch: 8 channels behind one address (0x70-0x77).
struct MuxConfig {
    std::string name;
    int bus = -1;  // index into Board::buses
    std::uint8_t address = 0x70;
    SourceLocation where;
};

inline constexpr int kMuxChannels = 8;

// A GPIO line as the kernel names it: gpiochipN and the line offset on that chip.
struct GpioLine {
    int chip = 0;
    int offset = 0;
    std::string text() const;
    bool operator==(const GpioLine&) const = default;
};

struct SensorConfig {
    std::string name;
    const hal::ChipInfo* chip = nullptr;
    Segment segment = Segment::Pelvis;
    int bus = -1;              // index into Board::buses
    int mux = -1;              // index into Board::muxes, or -1 when on the bus directly
    int channel = -1;          // mux channel 0-7, with mux
    std::uint8_t address = 0;  // I2C address of the accel/gyro die
    std::optional<std::uint8_t> magAddress;  // a separate magnetometer die
    int chipSelect = -1;                     // SPI
    int magChipSelect = -1;                  // SPI, separate magnetometer die
    std::optional<GpioLine> dataReady;       // none: poll the status bit on a timer at the ODR
    double odrHz = 0;                        // as configured
    double achievedOdrHz = 0;                // the chip's nearest rate
    double magOdrHz = 0;
    double accelRangeG = 16;
    double gyroRangeDps = 2000;
    Quatd mounting = Quatd::Identity();  // sensor frame -> segment frame (nominal)
    Vec3d positionM = Vec3d::Zero();     // on the segment, in the segment frame
    SourceLocation where;
};

enum class DisplayType { None, Framebuffer };

struct DisplayConfig {
    DisplayType type = DisplayType::None;
    std::string device;  // /dev/fbN
    double fps = 30;
};

// A live stream of the poses to one destination (docs/streams.md): `KIND:HOST:PORT[@RATE]`.
enum class StreamKind { Vmc, VrChat, Caphub };

struct StreamConfig {
    StreamKind kind = StreamKind::Vmc;
    std::string host;  // a name or an address (IPv4, or IPv6 in brackets)
    int port = 0;
    double rateHz = 60;  // the most datagrams (frames) per second
};

struct OutputsConfig {
    std::string recordings = "recordings";  // folder for .cap files
    std::string previewPng;                 // folder for PNG frames, empty: off
    std::string mjpeg;                      // host:port of the MJPEG stream, empty: off
    std::vector<StreamConfig> streams;      // live streams, none by default
};

// How the hub runs its capture threads (bus workers and the pipeline that publishes poses).
struct RuntimeConfig {
    // SCHED_FIFO priority of the capture threads (1-99; the pipeline one below the bus workers),
    // 0: the normal scheduler.
    int realtimePriority = 0;
    // CPUs the capture threads may run on (empty: any).
    std::vector<int> cpus;
    SourceLocation where;
};

// [body]: which segments the suit covers (board/body_layout.h, docs/sparse.md). Without the
// table the layout is none: a bench board of a few sensors anywhere.
struct BodyConfig {
    std::optional<BodyLayout> layout;
    SourceLocation where;  // of layout
};

struct Board {
    std::filesystem::path path;
    std::string text;  // the file as loaded: recordings embed it
    std::string name;
    std::string description;
    std::vector<BusConfig> buses;
    std::vector<MuxConfig> muxes;
    std::vector<SensorConfig> sensors;
    DisplayConfig display;
    OutputsConfig outputs;
    SubjectConfig subject;
    RuntimeConfig runtime;
    BodyConfig body;
};

// True when every bus of the board is simulated: the board is a virtual suit.
inline bool allBusesSimulated(const Board& b) {
    for (const auto& bus : b.buses) {
        if (bus.type != BusType::Sim) {
            return false;
        }
    }
    return true;
}

}  // namespace caphub::board
