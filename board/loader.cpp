#include "board/loader.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <toml++/toml.h>

#include "board/stream_spec.h"
#include "hal/core/error.h"
#include "hal/core/input_file.h"

namespace caphub::board {

std::string GpioLine::text() const {
    return fmt::format("gpiochip{}:{}", chip, offset);
}

Diagnostic::Diagnostic(SourceLocation whereIn, std::string keyIn, std::string messageIn)
    : where(std::move(whereIn)), key(std::move(keyIn)), message(std::move(messageIn)) {}

std::string Diagnostic::str() const {
    if (where.line <= 0) {  // about the file as a whole (it cannot be read)
        return fmt::format("{}: {}", where.file, message);
    }
    return fmt::format("{}:{}:{}: {}: {}", where.file, where.line, where.column, key, message);
}

namespace {

constexpr int kSchemaVersion = 1;

std::string_view typeName(const toml::node& n) {
    switch (n.type()) {
        case toml::node_type::string:
            return "a string";
        case toml::node_type::integer:
            return "an integer";
        case toml::node_type::floating_point:
            return "a number";
        case toml::node_type::boolean:
            return "a boolean";
        case toml::node_type::array:
            return "an array";
        case toml::node_type::table:
            return "a table";
        case toml::node_type::date:
        case toml::node_type::time:
        case toml::node_type::date_time:
            return "a date/time";
        default:
            return "nothing";
    }
}

std::string hex(int v) {
    return fmt::format("0x{:02x}", v);
}

std::string formatRate(double hz) {
    return fmt::format("{:g}", std::round(hz * 1000) / 1000);
}

template <typename Range, typename F>
std::string joinMapped(const Range& r, F f) {
    std::string out;
    for (const auto& x : r) {
        out += out.empty() ? "" : ", ";
        out += f(x);
    }
    return out;
}

// Walks the parsed document, turning it into a Board and collecting diagnostics.
class Parser {
public:
    Parser(std::string file, LoadResult& out) : file_(std::move(file)), out_(out) {}

    void run(const toml::table& root);

private:
    SourceLocation loc(const toml::source_region& r) const {
        return {file_, static_cast<int>(r.begin.line), static_cast<int>(r.begin.column)};
    }

    void error(const toml::source_region& r, std::string key, std::string message) {
        out_.errors.emplace_back(loc(r), std::move(key), std::move(message));
    }
    void error(const SourceLocation& l, std::string key, std::string message) {
        out_.errors.emplace_back(l, std::move(key), std::move(message));
    }
    void warning(const toml::source_region& r, std::string key, std::string message) {
        out_.warnings.emplace_back(loc(r), std::move(key), std::move(message));
    }

    static std::string join(const std::string& path, std::string_view key) {
        return path.empty() ? std::string(key) : path + "." + std::string(key);
    }

    void rejectUnknownKeys(const toml::table& t, const std::string& path,
                           std::initializer_list<std::string_view> allowed) {
        for (auto&& [k, v] : t) {
            if (std::find(allowed.begin(), allowed.end(), k.str()) == allowed.end()) {
                error(k.source(), join(path, k.str()),
                      fmt::format("unknown key (expected one of: {})", fmt::join(allowed, ", ")));
            }
        }
    }

    // A required or optional value of the table; reports a missing required key at the table
    // and a value of the wrong type at the value.
    const toml::node* find(const toml::table& t, std::string_view key, const std::string& path,
                           bool required, std::string_view expected) {
        const toml::node* n = t.get(key);
        if (n == nullptr && required) {
            error(t.source(), join(path, key),
                  fmt::format("missing required key (expected {})", expected));
        }
        return n;
    }

    std::optional<std::string> getString(const toml::table& t, std::string_view key,
                                         const std::string& path, bool required,
                                         std::string_view expected) {
        const toml::node* n = find(t, key, path, required, expected);
        if (n == nullptr) {
            return std::nullopt;
        }
        if (!n->is_string()) {
            error(n->source(), join(path, key),
                  fmt::format("expected {}, found {}", expected, typeName(*n)));
            return std::nullopt;
        }
        return n->as_string()->get();
    }

    std::optional<double> getNumber(const toml::table& t, std::string_view key,
                                    const std::string& path, bool required,
                                    std::string_view expected, double lo, double hi) {
        const toml::node* n = find(t, key, path, required, expected);
        if (n == nullptr) {
            return std::nullopt;
        }
        double v = 0;
        if (n->is_integer()) {
            v = static_cast<double>(n->as_integer()->get());
        } else if (n->is_floating_point()) {
            v = n->as_floating_point()->get();
        } else {
            error(n->source(), join(path, key),
                  fmt::format("expected {}, found {}", expected, typeName(*n)));
            return std::nullopt;
        }
        if (!std::isfinite(v)) {
            error(n->source(), join(path, key),
                  fmt::format("{} is not a finite number (expected {})", v, expected));
            return std::nullopt;
        }
        if (!(v >= lo && v <= hi)) {
            error(n->source(), join(path, key),
                  fmt::format("{:g} is out of range (expected {})", v, expected));
            return std::nullopt;
        }
        return v;
    }

    std::optional<std::int64_t> getInteger(const toml::table& t, std::string_view key,
                                           const std::string& path, bool required,
                                           std::string_view expected, std::int64_t lo,
                                           std::int64_t hi) {
        const toml::node* n = find(t, key, path, required, expected);
        if (n == nullptr) {
            return std::nullopt;
        }
        if (!n->is_integer()) {
            error(n->source(), join(path, key),
                  fmt::format("expected {}, found {}", expected, typeName(*n)));
            return std::nullopt;
        }
        const std::int64_t v = n->as_integer()->get();
        if (v < lo || v > hi) {
            error(n->source(), join(path, key),
                  fmt::format("{} is out of range (expected {})", v, expected));
            return std::nullopt;
        }
        return v;
    }

    // A fixed-size array of finite numbers, each within [lo, hi]; reports the first bad element
    // at its own position.
    template <std::size_t N>
    std::optional<std::array<double, N>> getNumbers(const toml::table& t, std::string_view key,
                                                    const std::string& path,
                                                    std::string_view expected, double lo,
                                                    double hi) {
        const toml::node* n = t.get(key);
        if (n == nullptr) {
            return std::nullopt;
        }
        const toml::array* a = n->as_array();
        if (a == nullptr || a->size() != N) {
            error(n->source(), join(path, key),
                  fmt::format("expected {}, found {}", expected, typeName(*n)));
            return std::nullopt;
        }
        std::array<double, N> out{};
        for (std::size_t i = 0; i < N; ++i) {
            const toml::node& e = *a->get(i);
            if (e.is_integer()) {
                out[i] = static_cast<double>(e.as_integer()->get());
            } else if (e.is_floating_point()) {
                out[i] = e.as_floating_point()->get();
            } else {
                error(e.source(), join(path, key),
                      fmt::format("expected {}, element {} is {}", expected, i, typeName(e)));
                return std::nullopt;
            }
            if (!std::isfinite(out[i])) {
                error(e.source(), join(path, key),
                      fmt::format("element {} is {}, not a finite number (expected {})", i, out[i],
                                  expected));
                return std::nullopt;
            }
            if (out[i] < lo || out[i] > hi) {
                error(e.source(), join(path, key),
                      fmt::format("element {} is {:g}, out of range (expected {})", i, out[i],
                                  expected));
                return std::nullopt;
            }
        }
        return out;
    }

    // The tables of a [[name]] array; reports anything else.
    std::vector<const toml::table*> arrayOfTables(const toml::table& root, std::string_view key,
                                                  bool required, std::string_view expected) {
        std::vector<const toml::table*> out;
        const toml::node* n = find(root, key, "", required, expected);
        if (n == nullptr) {
            return out;
        }
        const toml::array* a = n->as_array();
        if (a == nullptr || !a->is_array_of_tables()) {
            error(n->source(), std::string(key),
                  fmt::format("expected {} written as [[{}]] tables, found {}", expected, key,
                              typeName(*n)));
            return out;
        }
        for (const auto& e : *a) {
            out.push_back(e.as_table());
        }
        if (out.empty() && required) {
            error(n->source(), std::string(key), fmt::format("expected at least one {}", key));
        }
        return out;
    }

    const toml::table* subTable(const toml::table& root, std::string_view key) {
        const toml::node* n = root.get(key);
        if (n == nullptr) {
            return nullptr;
        }
        if (!n->is_table()) {
            error(n->source(), std::string(key),
                  fmt::format("expected a [{}] table, found {}", key, typeName(*n)));
            return nullptr;
        }
        return n->as_table();
    }

    void parseSubject(const toml::table& root);
    void parseBuses(const toml::table& root);
    void parseMuxes(const toml::table& root);
    void parseSensors(const toml::table& root);
    void parseSensor(const toml::table& t, const std::string& path);
    void parseBody(const toml::table& root);
    void parseDisplay(const toml::table& root);
    void parseOutputs(const toml::table& root);
    void parseRuntime(const toml::table& root);
    void checkBusClocks();
    void checkBudget();

    int busIndex(std::string_view name) const {
        for (std::size_t i = 0; i < board_.buses.size(); ++i) {
            if (board_.buses[i].name == name) {
                return static_cast<int>(i);
            }
        }
        return -1;
    }
    int muxIndex(std::string_view name) const {
        for (std::size_t i = 0; i < board_.muxes.size(); ++i) {
            if (board_.muxes[i].name == name) {
                return static_cast<int>(i);
            }
        }
        return -1;
    }

    // I2C devices seen so far: (bus, mux, channel, address) -> who.
    struct I2cDevice {
        int bus, mux, channel, address;
        std::string who;
    };
    void claimI2cAddress(const toml::source_region& r, const std::string& key, I2cDevice d);

    std::string file_;
    LoadResult& out_;
    Board board_;
    std::vector<I2cDevice> i2cDevices_;
    std::map<std::pair<int, int>, std::string> chipSelects_;  // (bus, cs) -> sensor
    std::vector<std::pair<GpioLine, std::string>> dataReadyLines_;
    std::map<Segment, std::string> segmentsTaken_;
    std::vector<std::string> sensorPaths_;
    std::vector<SourceLocation> busClockLoc_;
};

void Parser::run(const toml::table& root) {
    rejectUnknownKeys(root, "",
                      {"schema", "name", "description", "subject", "bus", "mux", "sensor",
                       "display", "outputs", "runtime", "body"});
    if (auto v = getInteger(root, "schema", "", true,
                            fmt::format("the board file format version, {}", kSchemaVersion), 1,
                            kSchemaVersion)) {
        (void)v;
    }
    if (auto v = getString(root, "name", "", true, "the board's name, a string")) {
        board_.name = *v;
        if (const std::string why = nameProblem("board", *v); !why.empty()) {
            error(root.get("name")->source(), "name", why);
        }
    }
    if (auto v = getString(root, "description", "", false, "a string")) {
        board_.description = *v;
    }
    parseSubject(root);
    parseBuses(root);
    parseMuxes(root);
    parseSensors(root);
    parseBody(root);
    parseDisplay(root);
    parseOutputs(root);
    parseRuntime(root);
    checkBusClocks();
    checkBudget();
    if (out_.errors.empty()) {
        out_.board = std::move(board_);
    }
}

void Parser::parseSubject(const toml::table& root) {
    const toml::table* t = subTable(root, "subject");
    if (t == nullptr) {
        return;
    }
    rejectUnknownKeys(*t, "subject", {"height_m", "mass_kg", "segment_lengths_m"});
    if (auto v = getNumber(*t, "height_m", "subject", false, "the subject's height, 0.5 to 2.5 m",
                           0.5, 2.5)) {
        board_.subject.heightM = *v;
    }
    if (auto v = getNumber(*t, "mass_kg", "subject", false, "the subject's mass, 10 to 300 kg", 10,
                           300)) {
        board_.subject.massKg = *v;
    }
    const toml::node* lengths = t->get("segment_lengths_m");
    if (lengths == nullptr) {
        return;
    }
    if (!lengths->is_table()) {
        error(
            lengths->source(), "subject.segment_lengths_m",
            fmt::format("expected a table of segment = length in m, found {}", typeName(*lengths)));
        return;
    }
    for (auto&& [k, v] : *lengths->as_table()) {
        const std::string key = "subject.segment_lengths_m." + std::string(k.str());
        const auto segment = findSegment(k.str());
        if (!segment) {
            error(k.source(), key,
                  fmt::format("unknown segment (expected one of: {})",
                              joinMapped(kSegments, [](const auto& s) { return s.name; })));
            continue;
        }
        if (auto len = getNumber(*lengths->as_table(), k.str(), "subject.segment_lengths_m", true,
                                 "a length of 0.01 to 1.5 m", 0.01, 1.5)) {
            board_.subject.segmentLengthsM.emplace_back(*segment, *len);
        }
    }
}

void Parser::parseBuses(const toml::table& root) {
    const auto tables = arrayOfTables(root, "bus", true, "the hub's buses");
    std::set<std::string> names;
    for (std::size_t i = 0; i < tables.size(); ++i) {
        const toml::table& t = *tables[i];
        const std::string path = fmt::format("bus[{}]", i);
        rejectUnknownKeys(t, path, {"name", "type", "protocol", "device", "clock_hz"});
        BusConfig bus;
        bus.where = loc(t.source());
        if (auto v = getString(t, "name", path, true, "the bus's name, a string")) {
            bus.name = *v;
            if (!names.insert(*v).second) {
                error(t.get("name")->source(), path + ".name",
                      fmt::format("bus name '{}' is used twice", *v));
            }
        }
        const auto type = getString(t, "type", path, true, "\"i2c\", \"spi\" or \"sim\"");
        bool typeOk = true;
        if (type) {
            if (*type == "i2c") {
                bus.type = BusType::I2c;
                bus.protocol = hal::BusProtocol::I2c;
            } else if (*type == "spi") {
                bus.type = BusType::Spi;
                bus.protocol = hal::BusProtocol::Spi;
            } else if (*type == "sim") {
                bus.type = BusType::Sim;
            } else {
                error(t.get("type")->source(), path + ".type",
                      fmt::format("unknown bus type '{}' (expected \"i2c\", \"spi\" or \"sim\")",
                                  *type));
                typeOk = false;
            }
        } else {
            typeOk = false;
        }
        const auto protocol =
            getString(t, "protocol", path, false, "\"i2c\" or \"spi\", the bus a sim bus models");
        if (protocol && typeOk) {
            if (bus.type != BusType::Sim) {
                error(t.get("protocol")->source(), path + ".protocol",
                      "only sim buses take a protocol (an i2c or spi bus is what its type says)");
            } else if (*protocol == "i2c") {
                bus.protocol = hal::BusProtocol::I2c;
            } else if (*protocol == "spi") {
                bus.protocol = hal::BusProtocol::Spi;
            } else {
                error(
                    t.get("protocol")->source(), path + ".protocol",
                    fmt::format("unknown protocol '{}' (expected \"i2c\" or \"spi\")", *protocol));
            }
        }
        if (typeOk) {
            const bool needsDevice = bus.type != BusType::Sim;
            const std::string_view expected = bus.type == BusType::I2c ? "a path like /dev/i2c-1"
                                              : bus.type == BusType::Spi
                                                  ? "a path like /dev/spidev0 (sensors add .CS)"
                                                  : "nothing: sim buses have no device";
            const auto device = getString(t, "device", path, needsDevice, expected);
            if (device) {
                const std::string_view prefix =
                    bus.type == BusType::I2c ? "/dev/i2c-" : "/dev/spidev";
                if (!needsDevice) {
                    error(t.get("device")->source(), path + ".device",
                          "sim buses have no device (remove the key, or make the bus i2c or spi)");
                } else if (device->rfind(prefix, 0) != 0 || device->size() == prefix.size()) {
                    error(t.get("device")->source(), path + ".device",
                          fmt::format("'{}' is not {}", *device, expected));
                } else {
                    bus.device = *device;
                }
            }
        }
        const bool i2c = bus.protocol == hal::BusProtocol::I2c;
        if (auto v = getNumber(t, "clock_hz", path, true,
                               i2c ? "the I2C clock, 10000 to 3400000 Hz"
                                   : "the SPI clock, 100000 to 100000000 Hz",
                               i2c ? 10e3 : 100e3, i2c ? 3.4e6 : 100e6)) {
            bus.clockHz = *v;
        } else {
            bus.clockHz = 0;  // no budget for a bus without a clock
        }
        busClockLoc_.push_back(t.get("clock_hz") ? loc(t.get("clock_hz")->source()) : bus.where);
        board_.buses.push_back(std::move(bus));
    }
}

void Parser::parseMuxes(const toml::table& root) {
    const auto tables = arrayOfTables(root, "mux", false, "TCA9548A I2C switches");
    std::set<std::string> names;
    for (std::size_t i = 0; i < tables.size(); ++i) {
        const toml::table& t = *tables[i];
        const std::string path = fmt::format("mux[{}]", i);
        rejectUnknownKeys(t, path, {"name", "chip", "bus", "address"});
        MuxConfig mux;
        mux.where = loc(t.source());
        if (auto v = getString(t, "name", path, true, "the mux's name, a string")) {
            mux.name = *v;
            if (!names.insert(*v).second) {
                error(t.get("name")->source(), path + ".name",
                      fmt::format("mux name '{}' is used twice", *v));
            }
        }
        if (auto v = getString(t, "chip", path, false, "\"tca9548a\"")) {
            if (*v != "tca9548a") {
                error(t.get("chip")->source(), path + ".chip",
                      fmt::format("unknown mux chip '{}' (expected \"tca9548a\")", *v));
            }
        }
        if (auto v = getString(t, "bus", path, true, "the name of an i2c bus")) {
            mux.bus = busIndex(*v);
            if (mux.bus < 0) {
                error(t.get("bus")->source(), path + ".bus", fmt::format("no bus named '{}'", *v));
            } else if (board_.buses[static_cast<std::size_t>(mux.bus)].protocol !=
                       hal::BusProtocol::I2c) {
                error(t.get("bus")->source(), path + ".bus",
                      fmt::format("bus '{}' is not an I2C bus; a TCA9548A sits on I2C", *v));
                mux.bus = -1;
            }
        }
        if (auto v = getInteger(t, "address", path, true, "the mux's address, 0x70 to 0x77", 0x70,
                                0x77)) {
            mux.address = static_cast<std::uint8_t>(*v);
            if (mux.bus >= 0) {
                claimI2cAddress(t.get("address")->source(), path + ".address",
                                {mux.bus, -1, -1, mux.address, "mux '" + mux.name + "'"});
            }
        }
        board_.muxes.push_back(std::move(mux));
    }
}

void Parser::claimI2cAddress(const toml::source_region& r, const std::string& key, I2cDevice d) {
    for (const auto& o : i2cDevices_) {
        if (o.bus != d.bus || o.address != d.address) {
            continue;
        }
        // A device on the bus itself answers whatever channel a mux has selected.
        const bool sameSegment =
            o.mux < 0 || d.mux < 0 || (o.mux == d.mux && o.channel == d.channel);
        if (!sameSegment) {
            continue;
        }
        const std::string where =
            d.mux < 0 ? "on the bus"
                      : fmt::format("on mux '{}' channel {}",
                                    board_.muxes[static_cast<std::size_t>(d.mux)].name, d.channel);
        error(r, key,
              fmt::format("address {} {} of bus '{}' is already taken by {}", hex(d.address), where,
                          board_.buses[static_cast<std::size_t>(d.bus)].name, o.who));
        return;
    }
    i2cDevices_.push_back(std::move(d));
}

void Parser::parseSensors(const toml::table& root) {
    const auto tables = arrayOfTables(root, "sensor", true, "the suit's sensors");
    for (std::size_t i = 0; i < tables.size(); ++i) {
        parseSensor(*tables[i], fmt::format("sensor[{}]", i));
    }
}

void Parser::parseSensor(const toml::table& t, const std::string& path) {
    rejectUnknownKeys(
        t, path,
        {"name", "segment", "chip", "bus", "mux", "channel", "address", "mag_address",
         "chip_select", "mag_chip_select", "drdy", "odr_hz", "mag_odr_hz", "accel_range_g",
         "gyro_range_dps", "mounting_quat", "mounting_euler_deg", "position_m"});
    SensorConfig s;
    s.where = loc(t.source());
    if (auto v = getString(t, "name", path, true, "the sensor's name, a string")) {
        s.name = *v;
        if (const std::string why = nameProblem("sensor", *v); !why.empty()) {
            error(t.get("name")->source(), path + ".name", why);
        }
        for (const auto& o : board_.sensors) {
            if (o.name == *v) {
                error(t.get("name")->source(), path + ".name",
                      fmt::format("sensor name '{}' is used twice", *v));
            }
        }
    }
    const std::string who = s.name.empty() ? path : "sensor '" + s.name + "'";

    if (auto v = getString(t, "segment", path, true, "the body segment the sensor is on")) {
        if (auto seg = findSegment(*v)) {
            s.segment = *seg;
            auto [it, fresh] = segmentsTaken_.emplace(*seg, who);
            if (!fresh) {
                error(t.get("segment")->source(), path + ".segment",
                      fmt::format("segment '{}' already has a sensor ({})", *v, it->second));
            }
        } else {
            error(t.get("segment")->source(), path + ".segment",
                  fmt::format("unknown segment '{}' (expected one of: {})", *v,
                              joinMapped(kSegments, [](const auto& x) { return x.name; })));
        }
    }

    if (auto v = getString(t, "chip", path, true, "the chip model")) {
        s.chip = hal::findChip(*v);
        if (s.chip == nullptr) {
            error(
                t.get("chip")->source(), path + ".chip",
                fmt::format("unknown chip '{}' (expected one of: {})", *v,
                            joinMapped(hal::chipCatalog(), [](const auto& c) { return c.name; })));
        }
    }

    if (auto v = getString(t, "bus", path, true, "the name of a bus")) {
        s.bus = busIndex(*v);
        if (s.bus < 0) {
            error(t.get("bus")->source(), path + ".bus", fmt::format("no bus named '{}'", *v));
        }
    }
    const BusConfig* bus = s.bus >= 0 ? &board_.buses[static_cast<std::size_t>(s.bus)] : nullptr;
    const bool i2c = bus != nullptr && bus->protocol == hal::BusProtocol::I2c;
    const bool spi = bus != nullptr && bus->protocol == hal::BusProtocol::Spi;

    // Mux and channel (on SPI both are reported below).
    if (spi) {
    } else if (auto v = getString(t, "mux", path, false, "the name of a mux")) {
        s.mux = muxIndex(*v);
        if (s.mux < 0) {
            error(t.get("mux")->source(), path + ".mux", fmt::format("no mux named '{}'", *v));
        } else if (bus != nullptr && board_.muxes[static_cast<std::size_t>(s.mux)].bus != s.bus) {
            error(t.get("mux")->source(), path + ".mux",
                  fmt::format("mux '{}' is not on bus '{}'", *v, bus->name));
            s.mux = -1;
        }
        if (auto c = getInteger(t, "channel", path, true, "the mux channel, 0 to 7", 0,
                                kMuxChannels - 1)) {
            s.channel = static_cast<int>(*c);
        }
    } else if (const toml::node* c = t.get("channel")) {
        error(c->source(), path + ".channel", "a channel needs a mux (add mux = \"...\")");
    }

    // Address on I2C, chip select on SPI.
    if (s.chip != nullptr && bus != nullptr) {
        const hal::ChipInfo& chip = *s.chip;
        const bool separateMag = !chip.magI2cAddresses.empty();
        if (i2c) {
            for (const char* key : {"chip_select", "mag_chip_select"}) {
                if (const toml::node* n = t.get(key)) {
                    error(n->source(), path + "." + key,
                          fmt::format("bus '{}' is I2C: give address, not {}", bus->name, key));
                }
            }
            const std::string addrs = joinMapped(chip.i2cAddresses, [](auto a) { return hex(a); });
            if (auto a = getInteger(t, "address", path, true,
                                    fmt::format("the I2C address of the {}: {}", chip.name, addrs),
                                    0, 0x7f)) {
                if (std::find(chip.i2cAddresses.begin(), chip.i2cAddresses.end(), *a) ==
                    chip.i2cAddresses.end()) {
                    error(t.get("address")->source(), path + ".address",
                          fmt::format("{} is not an address of the {} (expected {})",
                                      hex(static_cast<int>(*a)), chip.name, addrs));
                } else {
                    s.address = static_cast<std::uint8_t>(*a);
                    claimI2cAddress(t.get("address")->source(), path + ".address",
                                    {s.bus, s.mux, s.channel, s.address, who});
                }
            }
            if (separateMag) {
                const std::string magAddrs =
                    joinMapped(chip.magI2cAddresses, [](auto a) { return hex(a); });
                const auto m = getInteger(t, "mag_address", path, false,
                                          "the magnetometer's I2C address: " + magAddrs, 0, 0x7f);
                const int magAddress = m ? static_cast<int>(*m) : chip.magI2cAddresses.front();
                if (std::find(chip.magI2cAddresses.begin(), chip.magI2cAddresses.end(),
                              magAddress) == chip.magI2cAddresses.end()) {
                    error(t.get("mag_address")->source(), path + ".mag_address",
                          fmt::format("{} is not a magnetometer address of the {} (expected {})",
                                      hex(magAddress), chip.name, magAddrs));
                } else {
                    s.magAddress = static_cast<std::uint8_t>(magAddress);
                    const toml::node* n = t.get("mag_address");
                    claimI2cAddress(n ? n->source() : t.source(), path + ".mag_address",
                                    {s.bus, s.mux, s.channel, magAddress, who + " (magnetometer)"});
                }
            } else if (const toml::node* n = t.get("mag_address")) {
                error(n->source(), path + ".mag_address",
                      fmt::format("the {} has no separate magnetometer address", chip.name));
            }
        } else if (spi) {
            for (const char* key : {"address", "mag_address", "mux", "channel"}) {
                if (const toml::node* n = t.get(key)) {
                    error(n->source(), path + "." + key,
                          fmt::format("bus '{}' is SPI: give chip_select, not {}", bus->name, key));
                }
            }
            auto claim = [&](const char* key, int& out, const std::string& what) {
                if (auto cs =
                        getInteger(t, key, path, true, "the SPI chip select, 0 to 15", 0, 15)) {
                    out = static_cast<int>(*cs);
                    auto [it, fresh] = chipSelects_.emplace(std::pair{s.bus, out}, what);
                    if (!fresh) {
                        error(t.get(key)->source(), path + "." + key,
                              fmt::format("chip select {} of bus '{}' is already taken by {}", out,
                                          bus->name, it->second));
                    }
                }
            };
            claim("chip_select", s.chipSelect, who);
            if (separateMag) {
                claim("mag_chip_select", s.magChipSelect, who + " (magnetometer)");
            } else if (const toml::node* n = t.get("mag_chip_select")) {
                error(n->source(), path + ".mag_chip_select",
                      fmt::format("the {} has no separate magnetometer die", chip.name));
            }
        }
    }

    // Data-ready line.
    if (auto v = getString(t, "drdy", path, false, "a GPIO line, gpiochipN:offset")) {
        unsigned chipNo = 0;
        unsigned offset = 0;
        int consumed = 0;
        const bool parsed =
            std::sscanf(v->c_str(), "gpiochip%u:%u%n", &chipNo, &offset, &consumed) == 2 &&
            static_cast<std::size_t>(consumed) == v->size() &&
            v->find_first_of(" +-") == std::string::npos && chipNo < 64 && offset < 1024;
        if (!parsed) {
            error(t.get("drdy")->source(), path + ".drdy",
                  fmt::format("'{}' is not a GPIO line (expected gpiochipN:offset, e.g. "
                              "\"gpiochip0:17\")",
                              *v));
        } else {
            const GpioLine line{static_cast<int>(chipNo), static_cast<int>(offset)};
            for (const auto& [other, name] : dataReadyLines_) {
                if (other == line) {
                    error(t.get("drdy")->source(), path + ".drdy",
                          fmt::format("line {} is already the data-ready line of {}", *v, name));
                }
            }
            dataReadyLines_.emplace_back(line, who);
            s.dataReady = line;
        }
    }

    // Rates and ranges.
    if (auto v =
            getNumber(t, "odr_hz", path, true, "the output data rate, 1 to 10000 Hz", 1, 10000)) {
        s.odrHz = *v;
        if (s.chip != nullptr) {
            if (hal::odrSupported(*s.chip, *v)) {
                s.achievedOdrHz = s.chip->nearestOdrHz(*v);
            } else {
                const auto near = hal::odrNeighbours(*s.chip, *v);
                error(t.get("odr_hz")->source(), path + ".odr_hz",
                      fmt::format("the {} cannot run at {} Hz (it runs at {}; nearest: {} Hz)",
                                  s.chip->name, formatRate(*v), s.chip->odrRule,
                                  joinMapped(near, formatRate)));
            }
        }
    }
    if (s.chip != nullptr) {
        const auto& rates = s.chip->magOdrsHz;
        if (auto v = getNumber(t, "mag_odr_hz", path, false, "the magnetometer rate in Hz", 0.1,
                               10000)) {
            if (std::find(rates.begin(), rates.end(), *v) == rates.end()) {
                error(t.get("mag_odr_hz")->source(), path + ".mag_odr_hz",
                      fmt::format("the {} magnetometer cannot run at {} Hz (expected one of: {})",
                                  s.chip->name, formatRate(*v), joinMapped(rates, formatRate)));
            } else {
                s.magOdrHz = *v;
            }
        } else if (s.achievedOdrHz > 0 && !rates.empty()) {
            // Default: the fastest magnetometer rate up to the sample rate, at most 100 Hz. A
            // chip without a list of its own (imported samples) reads it with every sample.
            const double cap = std::min(s.achievedOdrHz, 100.0);
            s.magOdrHz = rates.front();
            for (double r : rates) {
                if (r <= cap) {
                    s.magOdrHz = std::max(s.magOdrHz, r);
                }
            }
        }
        auto range = [&](const char* key, std::span<const double> allowed, const char* unit,
                         double& out) {
            const std::string list =
                joinMapped(allowed, [](double x) { return fmt::format("{:g}", x); });
            if (auto v = getNumber(t, key, path, false,
                                   fmt::format("a full scale in {}: {}", unit, list), 0, 1e6)) {
                if (std::find(allowed.begin(), allowed.end(), *v) == allowed.end()) {
                    error(t.get(key)->source(), path + "." + key,
                          fmt::format("the {} has no {:g} {} range (expected one of: {})",
                                      s.chip->name, *v, unit, list));
                } else {
                    out = *v;
                }
            } else {
                out = allowed.back();
            }
        };
        range("accel_range_g", s.chip->accelRangesG, "g", s.accelRangeG);
        range("gyro_range_dps", s.chip->gyroRangesDps, "dps", s.gyroRangeDps);
    }

    // Mounting: sensor frame -> segment frame.
    const toml::node* quat = t.get("mounting_quat");
    const toml::node* euler = t.get("mounting_euler_deg");
    if (quat != nullptr && euler != nullptr) {
        error(euler->source(), path + ".mounting_euler_deg",
              "give the mounting either as mounting_quat or as mounting_euler_deg, not both");
    } else if (auto q = getNumbers<4>(t, "mounting_quat", path,
                                      "a unit quaternion, 4 numbers [w, x, y, z] within +-1",
                                      -1.001, 1.001)) {
        // Elements up to 1.001: the norm below is allowed 1e-3 of slack.
        const Quatd qq((*q)[0], (*q)[1], (*q)[2], (*q)[3]);
        const double n = quatNorm(qq);
        if (std::abs(n - 1.0) > 1e-3) {
            error(quat->source(), path + ".mounting_quat",
                  fmt::format("not a unit quaternion (norm {:.6g}, expected 1)", n));
        } else {
            s.mounting = qq.normalized();
        }
    } else if (auto e =
                   getNumbers<3>(t, "mounting_euler_deg", path,
                                 "3 angles in degrees [x, y, z], each within +-360", -360, 360)) {
        constexpr double kDeg = 3.14159265358979323846 / 180.0;
        // Rotations about the segment's fixed x, then y, then z axes = intrinsic Z-Y-X.
        Quatd fromEuler;
        (void)fromEulerIntrinsic("ZYX", Vec3d((*e)[2] * kDeg, (*e)[1] * kDeg, (*e)[0] * kDeg),
                                 fromEuler);
        s.mounting = fromEuler;
    }
    if (auto p = getNumbers<3>(t, "position_m", path,
                               "3 numbers [x, y, z] in m, each within +-1 m: a sensor sits "
                               "within 1 m of its segment's origin",
                               -1, 1)) {
        s.positionM = Vec3d((*p)[0], (*p)[1], (*p)[2]);
    }
    sensorPaths_.push_back(path);
    board_.sensors.push_back(std::move(s));
}

void Parser::parseBody(const toml::table& root) {
    std::vector<Segment> segments;
    for (const auto& s : board_.sensors) {
        segments.push_back(s.segment);
    }
    const toml::table* t = subTable(root, "body");
    if (t == nullptr) {
        // No layout named: a board of a few sensors on a bench is fine, but a body without a
        // pelvis sensor cannot be solved; say so without failing the board.
        if (!board_.sensors.empty() && !segmentsTaken_.contains(Segment::Pelvis)) {
            out_.warnings.emplace_back(
                SourceLocation{file_, 1, 1}, "body",
                "no sensor on the pelvis: the body's poses will hold the pelvis upright, facing "
                "north (a suit needs one; docs/sparse.md)");
        }
        return;
    }
    rejectUnknownKeys(*t, "body", {"layout"});
    const std::string expected = "\"full\", \"upper10\", \"lower7\" or \"sparse\"";
    const auto v = getString(*t, "layout", "body", true, expected);
    if (!v) {
        return;
    }
    const toml::source_region where = t->get("layout")->source();
    const auto layout = parseBodyLayout(*v);
    if (!layout) {
        error(where, "body.layout", fmt::format("unknown layout '{}' (expected {})", *v, expected));
        return;
    }
    if (segmentsTaken_.size() != board_.sensors.size()) {
        return;  // a sensor's segment is already in error
    }
    if (const std::string why = layoutMismatch(*layout, segments); !why.empty()) {
        error(where, "body.layout", why);
        return;
    }
    board_.body.layout = *layout;
    board_.body.where = loc(where);
}

void Parser::parseDisplay(const toml::table& root) {
    const toml::table* t = subTable(root, "display");
    if (t == nullptr) {
        return;
    }
    rejectUnknownKeys(*t, "display", {"type", "device", "fps"});
    if (auto v = getString(*t, "type", "display", true, "\"none\" or \"framebuffer\"")) {
        if (*v == "none") {
            board_.display.type = DisplayType::None;
        } else if (*v == "framebuffer") {
            board_.display.type = DisplayType::Framebuffer;
            if (auto d = getString(*t, "device", "display", true, "a path like /dev/fb1")) {
                if (d->rfind("/dev/fb", 0) != 0 || d->size() == 7) {
                    error(t->get("device")->source(), "display.device",
                          fmt::format("'{}' is not a framebuffer device (expected /dev/fbN)", *d));
                } else {
                    board_.display.device = *d;
                }
            }
        } else {
            error(t->get("type")->source(), "display.type",
                  fmt::format("unknown display type '{}' (expected \"none\" or \"framebuffer\")",
                              *v));
        }
    }
    if (auto v = getNumber(*t, "fps", "display", false, "frames per second, 1 to 120", 1, 120)) {
        board_.display.fps = *v;
    }
}

void Parser::parseOutputs(const toml::table& root) {
    const toml::table* t = subTable(root, "outputs");
    if (t == nullptr) {
        return;
    }
    rejectUnknownKeys(*t, "outputs", {"recordings", "preview_png", "mjpeg", "streams"});
    if (auto v = getString(*t, "recordings", "outputs", false, "a folder for recordings")) {
        board_.outputs.recordings = *v;
    }
    if (auto v = getString(*t, "preview_png", "outputs", false, "a folder for PNG frames")) {
        board_.outputs.previewPng = *v;
    }
    if (auto v = getString(*t, "mjpeg", "outputs", false, "host:port, e.g. \"127.0.0.1:8080\"")) {
        const auto colon = v->rfind(':');
        int port = 0;
        std::istringstream in(colon == std::string::npos ? "" : v->substr(colon + 1));
        const bool ok = colon != std::string::npos && colon > 0 && (in >> port) && in.eof() &&
                        port > 0 && port < 65536;
        if (!ok) {
            error(t->get("mjpeg")->source(), "outputs.mjpeg",
                  fmt::format("'{}' is not host:port (e.g. \"127.0.0.1:8080\")", *v));
        } else {
            board_.outputs.mjpeg = *v;
        }
    }
    if (const toml::node* n = t->get("streams")) {
        const toml::array* a = n->as_array();
        if (a == nullptr) {
            error(n->source(), "outputs.streams",
                  fmt::format("expected an array of \"KIND:HOST:PORT[@RATE]\" strings, found {}",
                              typeName(*n)));
            return;
        }
        for (std::size_t i = 0; i < a->size(); ++i) {
            const toml::node& e = *a->get(i);
            if (!e.is_string()) {
                error(
                    e.source(), "outputs.streams",
                    fmt::format("element {}: expected a \"KIND:HOST:PORT[@RATE]\" string, found {}",
                                i, typeName(e)));
                continue;
            }
            auto spec = parseStreamSpec(e.as_string()->get());
            if (!spec) {
                error(e.source(), "outputs.streams",
                      fmt::format("element {}: {}", i, spec.error().message));
                continue;
            }
            board_.outputs.streams.push_back(*spec);
        }
    }
}

void Parser::parseRuntime(const toml::table& root) {
    const toml::table* t = subTable(root, "runtime");
    if (t == nullptr) {
        return;
    }
    board_.runtime.where = loc(t->source());
    rejectUnknownKeys(*t, "runtime", {"realtime_priority", "cpus"});
    if (auto v =
            getInteger(*t, "realtime_priority", "runtime", false,
                       "a SCHED_FIFO priority, 1 to 99, or 0 for the normal scheduler", 0, 99)) {
        board_.runtime.realtimePriority = static_cast<int>(*v);
    }
    const toml::node* n = t->get("cpus");
    if (n == nullptr) {
        return;
    }
    const toml::array* a = n->as_array();
    const std::string expected = "an array of CPU numbers, e.g. [2, 3]";
    if (a == nullptr || a->empty()) {
        error(n->source(), "runtime.cpus",
              fmt::format("expected {}, found {}", expected,
                          a == nullptr ? typeName(*n) : std::string_view("an empty array")));
        return;
    }
    for (const auto& e : *a) {
        if (!e.is_integer() || e.as_integer()->get() < 0 || e.as_integer()->get() > 1023) {
            error(e.source(), "runtime.cpus",
                  fmt::format("expected {}, CPU numbers 0 to 1023", expected));
            return;
        }
        const int cpu = static_cast<int>(e.as_integer()->get());
        if (std::find(board_.runtime.cpus.begin(), board_.runtime.cpus.end(), cpu) !=
            board_.runtime.cpus.end()) {
            error(e.source(), "runtime.cpus", fmt::format("CPU {} is listed twice", cpu));
            return;
        }
        board_.runtime.cpus.push_back(cpu);
    }
}

void Parser::checkBusClocks() {
    for (std::size_t b = 0; b < board_.buses.size(); ++b) {
        const BusConfig& bus = board_.buses[b];
        if (bus.clockHz <= 0) {
            continue;
        }
        for (const auto& s : board_.sensors) {
            if (s.bus != static_cast<int>(b) || s.chip == nullptr) {
                continue;
            }
            const double max =
                bus.protocol == hal::BusProtocol::I2c ? s.chip->maxI2cHz : s.chip->maxSpiHz;
            if (bus.clockHz > max) {
                error(busClockLoc_[b], fmt::format("bus[{}].clock_hz", b),
                      fmt::format("{:g} Hz is faster than the {} of sensor '{}' allows on {} ({:g} "
                                  "Hz)",
                                  bus.clockHz, s.chip->name, s.name, hal::toString(bus.protocol),
                                  max));
                break;
            }
        }
    }
}

void Parser::checkBudget() {
    out_.loads = computeBusLoads(board_);
    for (const BusLoad& load : out_.loads) {
        const BusConfig& bus = board_.buses[static_cast<std::size_t>(load.bus)];
        if (load.utilisation > kMaxBusUtilisation) {
            error(bus.where, fmt::format("bus[{}]", load.bus),
                  fmt::format("bus '{}' would be busy {:.1f}% of the time ({:.0f} transactions/s, "
                              "{:.0f} bytes/s at {:g} Hz), over the {:.0f}% budget: lower odr_hz, "
                              "raise clock_hz or move sensors to another bus",
                              bus.name, load.utilisation * 100, load.transactionsPerS,
                              load.bytesPerS, bus.clockHz, kMaxBusUtilisation * 100));
        }
    }
}

}  // namespace

LoadResult loadBoardText(std::string_view text, const std::string& sourceName) {
    LoadResult out;
    toml::table root;
    try {
        root = toml::parse(text, sourceName);
    } catch (const toml::parse_error& e) {
        const auto& b = e.source().begin;
        SourceLocation where;
        where.file = sourceName;
        where.line = static_cast<int>(b.line);
        where.column = static_cast<int>(b.column);
        out.errors.emplace_back(std::move(where), "(syntax)",
                                fmt::format("TOML syntax error: {}", e.description()));
        return out;
    }
    Parser(sourceName, out).run(root);
    if (out.board) {
        out.board->path = sourceName;
        out.board->text = std::string(text);
    }
    return out;
}

std::string nameProblem(std::string_view what, std::string_view name) {
    constexpr std::size_t kMaxLength = 64;
    const auto allowed = [](char c) {
        return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
               c == '_' || c == '-' || c == '.';
    };
    if (name.empty() || name.size() > kMaxLength || name.front() == '.' || name.front() == '-' ||
        !std::all_of(name.begin(), name.end(), allowed)) {
        return fmt::format(
            "{} name '{}': expected 1 to {} letters, digits, '_', '-' or '.', not starting "
            "with '.' or '-' (the name names files and web addresses)",
            what, name, kMaxLength);
    }
    return {};
}

LoadResult loadBoardFile(const std::filesystem::path& path) {
    auto text = readInputFile(path, kMaxBoardFileBytes);
    if (!text) {
        LoadResult out;
        SourceLocation where;
        where.file = path.string();
        const std::string& why = text.error().message;
        out.errors.emplace_back(
            std::move(where), "(file)",
            text.error().code == EFBIG
                ? fmt::format("cannot read the board file: {}: a recording embeds the board file "
                              "in its metadata, which holds at most {} bytes (1 MiB)",
                              why, kMaxBoardFileBytes)
                : fmt::format("cannot read the board file: {}", why));
        return out;
    }
    return loadBoardText(*text, path.string());
}

}  // namespace caphub::board
