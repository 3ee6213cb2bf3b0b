// The board file loader: every class of mistake is reported with the file, the line and the key,
// and a good file becomes a Board.
#include "board/loader.h"

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace caphub::board {
namespace {

using ::testing::HasSubstr;

// A valid two-sensor board; tests change one thing in it.
const std::string kHeader = R"(schema = 1
name = "test"

[[bus]]
name = "i2c1"
type = "i2c"
device = "/dev/i2c-1"
clock_hz = 400000

[[mux]]
name = "mux0"
bus = "i2c1"
address = 0x70
)";

std::string sensor(const std::string& name, const std::string& segment, int channel, int address,
                   const std::string& extra = "") {
    return "\n[[sensor]]\nname = \"" + name + "\"\nsegment = \"" + segment +
           "\"\nchip = \"icm20948\"\nbus = \"i2c1\"\nmux = \"mux0\"\nchannel = " +
           std::to_string(channel) + "\naddress = " + std::to_string(address) + "\nodr_hz = 100\n" +
           extra;
}

LoadResult load(const std::string& text) {
    return loadBoardText(text, "test.toml");
}

// The line (1-based) of the first occurrence of needle in text.
int lineOf(const std::string& text, const std::string& needle, std::size_t from = 0) {
    const auto pos = text.find(needle, from);
    EXPECT_NE(pos, std::string::npos) << needle;
    return 1 +
           static_cast<int>(std::count(text.begin(), text.begin() + static_cast<long>(pos), '\n'));
}

void expectOneError(const LoadResult& r, const std::string& key, int line,
                    const std::string& messagePart) {
    ASSERT_FALSE(r.ok());
    ASSERT_EQ(r.errors.size(), 1u) << r.errors[0].str();
    const Diagnostic& d = r.errors[0];
    EXPECT_EQ(d.where.file, "test.toml");
    EXPECT_EQ(d.key, key) << d.str();
    EXPECT_EQ(d.where.line, line) << d.str();
    EXPECT_THAT(d.message, HasSubstr(messagePart)) << d.str();
}

TEST(BoardLoader, AcceptsAValidBoard) {
    const auto r = load(kHeader + sensor("a", "pelvis", 0, 0x68) + sensor("b", "t12", 0, 0x69));
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    const Board& b = *r.board;
    EXPECT_EQ(b.name, "test");
    ASSERT_EQ(b.sensors.size(), 2u);
    EXPECT_EQ(b.sensors[1].segment, Segment::T12);
    EXPECT_EQ(b.sensors[1].address, 0x69);
    EXPECT_EQ(b.sensors[0].mux, 0);
    EXPECT_EQ(b.sensors[0].achievedOdrHz, 100.0);
    EXPECT_EQ(b.sensors[0].magOdrHz, 100.0);
    EXPECT_EQ(b.buses[0].device, "/dev/i2c-1");
    ASSERT_EQ(r.loads.size(), 1u);
    EXPECT_GT(r.loads[0].utilisation, 0.0);
}

TEST(BoardLoader, ReportsATomlSyntaxErrorWithItsLine) {
    const std::string text = kHeader + "\n[[sensor]]\nname = \"a\nsegment = \"pelvis\"\n";
    const auto r = load(text);
    ASSERT_EQ(r.errors.size(), 1u);
    EXPECT_EQ(r.errors[0].key, "(syntax)");
    EXPECT_EQ(r.errors[0].where.line, lineOf(text, "name = \"a"));
    EXPECT_THAT(r.errors[0].message, HasSubstr("TOML syntax error"));
}

TEST(BoardLoader, ReportsAnUnknownChip) {
    const std::string s = sensor("a", "pelvis", 0, 0x68);
    std::string text = kHeader + s;
    text.replace(text.find("icm20948"), 8, "mpu9250");
    expectOneError(load(text), "sensor[0].chip", lineOf(text, "mpu9250"), "unknown chip 'mpu9250'");
}

// A board's and a sensor's name name files: a board named "../../x" made `caphub run` record
// outside its folder, a sensor named "../x" made `caphub sim --all` write outside its, and a
// name with spaces or '#' made the magnetometer state file unreadable.
TEST(BoardLoader, ReportsASensorNameThatCannotNameAFile) {
    for (const std::string& bad :
         std::vector<std::string>{"../x", "a/b", "left foot", "a#b", ".hidden", "-a", "",
                                  std::string(65, 'a'), "\u00e9"}) {
        const std::string text = kHeader + sensor(bad, "pelvis", 0, 0x68);
        expectOneError(load(text), "sensor[0].name", lineOf(text, "name = \"" + bad + "\""),
                       "expected 1 to 64 letters, digits");
    }
    for (const std::string& good :
         std::vector<std::string>{"l_foot", "IMU-3", "imu.3", "00B421AF", std::string(64, 'a')}) {
        const auto r = load(kHeader + sensor(good, "pelvis", 0, 0x68));
        EXPECT_TRUE(r.ok()) << good << ": " << r.errors[0].str();
    }
}

TEST(BoardLoader, ReportsABoardNameThatCannotNameAFile) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("name = \"test\""), 13, "name = \"../../x\"");
    expectOneError(load(text), "name", 2, "board name '../../x': expected 1 to 64 letters");
}

TEST(BoardLoader, ReportsAnUnknownSegmentAndListsTheKnownOnes) {
    const std::string text = kHeader + sensor("a", "tail", 0, 0x68);
    const auto r = load(text);
    expectOneError(r, "sensor[0].segment", lineOf(text, "\"tail\""), "unknown segment 'tail'");
    EXPECT_THAT(r.errors[0].message, HasSubstr("l_forearm"));
}

TEST(BoardLoader, ReportsTwoSensorsAtOneAddressOnTheSameMuxChannel) {
    const std::string text = kHeader + sensor("a", "pelvis", 3, 0x68) + sensor("b", "t12", 3, 0x68);
    const int line = lineOf(text, "address = 104", text.find("name = \"b\""));
    expectOneError(load(text), "sensor[1].address", line, "already taken by sensor 'a'");
}

TEST(BoardLoader, AllowsOneAddressOnDifferentMuxChannels) {
    const auto r = load(kHeader + sensor("a", "pelvis", 3, 0x68) + sensor("b", "t12", 4, 0x68));
    EXPECT_TRUE(r.ok());
}

TEST(BoardLoader, ADeviceOnTheBusItselfCollidesWithEveryChannel) {
    std::string direct = sensor("b", "t12", 0, 0x68);
    direct.replace(direct.find("mux = \"mux0\"\nchannel = 0\n"), 25, "");
    const std::string text = kHeader + sensor("a", "pelvis", 5, 0x68) + direct;
    const auto r = load(text);
    ASSERT_EQ(r.errors.size(), 1u);
    EXPECT_EQ(r.errors[0].key, "sensor[1].address");
}

TEST(BoardLoader, ReportsAMalformedDataReadyLine) {
    for (const std::string& bad :
         std::vector<std::string>{"gpio0:17", "gpiochip0", "gpiochip0:", "gpiochip0:x",
                                  "gpiochip0:17:1", "gpiochip-1:3", "gpiochip0: 17"}) {
        const std::string text =
            kHeader + sensor("a", "pelvis", 0, 0x68, "drdy = \"" + bad + "\"\n");
        expectOneError(load(text), "sensor[0].drdy", lineOf(text, "drdy"), "is not a GPIO line");
    }
}

TEST(BoardLoader, ParsesADataReadyLine) {
    const auto r = load(kHeader + sensor("a", "pelvis", 0, 0x68, "drdy = \"gpiochip1:27\"\n"));
    ASSERT_TRUE(r.ok());
    ASSERT_TRUE(r.board->sensors[0].dataReady);
    EXPECT_EQ(r.board->sensors[0].dataReady->chip, 1);
    EXPECT_EQ(r.board->sensors[0].dataReady->offset, 27);
}

TEST(BoardLoader, ReportsTwoSensorsOnOneDataReadyLine) {
    const std::string text = kHeader + sensor("a", "pelvis", 0, 0x68, "drdy = \"gpiochip0:4\"\n") +
                             sensor("b", "t12", 0, 0x69, "drdy = \"gpiochip0:4\"\n");
    const int line = lineOf(text, "drdy", text.find("name = \"b\""));
    expectOneError(load(text), "sensor[1].drdy", line, "already the data-ready line of sensor 'a'");
}

TEST(BoardLoader, ReportsAnOdrTheChipCannotDoWithTheNearestRates) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("odr_hz = 100"), 12, "odr_hz = 200");
    const auto r = load(text);
    expectOneError(r, "sensor[0].odr_hz", lineOf(text, "odr_hz"), "cannot run at 200 Hz");
    EXPECT_THAT(r.errors[0].message, HasSubstr("183.333"));
    EXPECT_THAT(r.errors[0].message, HasSubstr("220"));
}

TEST(BoardLoader, ReportsABusOverBudget) {
    // Eight sensors at 1100 Hz on a 400 kHz bus: far beyond it.
    std::string text = kHeader;
    const char* segments[] = {"pelvis", "t12", "skull", "l5", "c7", "l_hand", "r_hand", "l_thigh"};
    for (int i = 0; i < 8; ++i) {
        std::string s = sensor("s" + std::to_string(i), segments[i], i / 2, 0x68 + i % 2);
        s.replace(s.find("odr_hz = 100"), 12, "odr_hz = 1100");
        text += s;
    }
    const auto r = load(text);
    expectOneError(r, "bus[0]", lineOf(text, "[[bus]]"), "over the 80% budget");
    ASSERT_EQ(r.loads.size(), 1u);
    EXPECT_GT(r.loads[0].utilisation, 0.8);
}

TEST(BoardLoader, ReportsAMissingRequiredKeyAtItsTable) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("odr_hz = 100\n"), 13, "");
    expectOneError(load(text), "sensor[0].odr_hz", lineOf(text, "[[sensor]]"),
                   "missing required key");
}

TEST(BoardLoader, ReportsAMissingSchema) {
    const std::string text =
        kHeader.substr(kHeader.find('\n') + 1) + sensor("a", "pelvis", 0, 0x68);
    expectOneError(load(text), "schema", 1, "missing required key");
}

TEST(BoardLoader, ReportsAnUnknownKey) {
    const std::string text = kHeader + sensor("a", "pelvis", 0, 0x68, "odr = 100\n");
    expectOneError(load(text), "sensor[0].odr", lineOf(text, "odr = 100"), "unknown key");
}

TEST(BoardLoader, ReportsAValueOfTheWrongType) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("odr_hz = 100"), 12, "odr_hz = \"fast\"");
    expectOneError(load(text), "sensor[0].odr_hz", lineOf(text, "odr_hz"), "found a string");
}

TEST(BoardLoader, ReportsAnAddressTheChipDoesNotHave) {
    const std::string text = kHeader + sensor("a", "pelvis", 0, 0x6A);
    expectOneError(load(text), "sensor[0].address", lineOf(text, "address = 106"),
                   "is not an address of the icm20948");
}

TEST(BoardLoader, ReportsAMuxChannelOutOfRange) {
    const std::string text = kHeader + sensor("a", "pelvis", 8, 0x68);
    expectOneError(load(text), "sensor[0].channel", lineOf(text, "channel = 8"), "0 to 7");
}

TEST(BoardLoader, ReportsAnUnknownBusAndMux) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("bus = \"i2c1\"\nmux"), 12, "bus = \"i2c9\"");
    const auto r = load(text);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.errors[0].key, "sensor[0].bus");
    EXPECT_THAT(r.errors[0].message, HasSubstr("no bus named 'i2c9'"));
}

TEST(BoardLoader, ReportsTwoSensorsOnOneSegment) {
    const std::string text =
        kHeader + sensor("a", "pelvis", 0, 0x68) + sensor("b", "pelvis", 0, 0x69);
    const int line = lineOf(text, "segment", text.find("name = \"b\""));
    expectOneError(load(text), "sensor[1].segment", line, "already has a sensor (sensor 'a')");
}

TEST(BoardLoader, ReportsABusClockAboveWhatTheChipAllows) {
    std::string text = kHeader + sensor("a", "pelvis", 0, 0x68);
    text.replace(text.find("clock_hz = 400000"), 17, "clock_hz = 1000000");
    expectOneError(load(text), "bus[0].clock_hz", lineOf(text, "clock_hz"),
                   "faster than the icm20948");
}

TEST(BoardLoader, ReportsTwoMuxesAtOneAddress) {
    const std::string text = kHeader +
                             "\n[[mux]]\nname = \"mux1\"\nbus = \"i2c1\"\naddress = 0x70\n" +
                             sensor("a", "pelvis", 0, 0x68);
    expectOneError(load(text), "mux[1].address", lineOf(text, "address = 0x70", text.find("mux1")),
                   "already taken by mux 'mux0'");
}

TEST(BoardLoader, SpiSensorsTakeChipSelectsNotAddresses) {
    const std::string text = R"(schema = 1
name = "spi"
[[bus]]
name = "spi0"
type = "spi"
device = "/dev/spidev0"
clock_hz = 7000000
[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "spi0"
chip_select = 0
odr_hz = 1100
[[sensor]]
name = "b"
segment = "t12"
chip = "lsm6dsox+lis3mdl"
bus = "spi0"
chip_select = 0
mag_chip_select = 1
odr_hz = 104
)";
    const auto r = load(text);
    expectOneError(r, "sensor[1].chip_select", lineOf(text, "chip_select = 0", text.find("\"b\"")),
                   "chip select 0 of bus 'spi0' is already taken by sensor 'a'");
}

TEST(BoardLoader, LsmSensorGetsItsMagnetometerAddressAndRates) {
    const std::string text = R"(schema = 1
name = "lsm"
[[bus]]
name = "sim0"
type = "sim"
clock_hz = 400000
[[sensor]]
name = "a"
segment = "l_hand"
chip = "lsm6dsox+lis3mdl"
bus = "sim0"
address = 0x6a
odr_hz = 104
)";
    const auto r = load(text);
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    const auto& s = r.board->sensors[0];
    ASSERT_TRUE(s.magAddress);
    EXPECT_EQ(*s.magAddress, 0x1C);
    EXPECT_EQ(s.magOdrHz, 80.0);  // fastest LIS3MDL rate up to min(104, 100) Hz
    EXPECT_EQ(s.accelRangeG, 16.0);
}

TEST(BoardLoader, MountingFromEulerAnglesAndQuaternions) {
    auto r = load(kHeader + sensor("a", "pelvis", 0, 0x68, "mounting_euler_deg = [0, 0, 90]\n"));
    ASSERT_TRUE(r.ok());
    // 90 deg about the segment's z: the sensor's x axis lies along the segment's y.
    EXPECT_LT((r.board->sensors[0].mounting * Vec3d::UnitX() - Vec3d::UnitY()).norm(), 1e-12);

    r = load(kHeader + sensor("a", "pelvis", 0, 0x68, "mounting_quat = [0.5, 0.5, 0.5, 0.5]\n"));
    ASSERT_TRUE(r.ok());
    EXPECT_NEAR(r.board->sensors[0].mounting.w(), 0.5, 1e-15);

    const std::string bad =
        kHeader + sensor("a", "pelvis", 0, 0x68, "mounting_quat = [1, 1, 0, 0]\n");
    expectOneError(load(bad), "sensor[0].mounting_quat", lineOf(bad, "mounting_quat"),
                   "not a unit quaternion");
}

// A glitched or hostile board file must not put a non-finite or absurd number into the capture:
// each array element is checked, and the error points at the element itself.
TEST(BoardLoader, RejectsNonFiniteOrOutOfRangeMountingAndPosition) {
    struct Case {
        std::string line, key, element, message;
    };
    const Case cases[] = {
        {"mounting_euler_deg = [nan, 180, 0]", "mounting_euler_deg", "nan",
         "element 0 is nan, not a finite number"},
        {"mounting_euler_deg = [0, inf, 0]", "mounting_euler_deg", "inf",
         "element 1 is inf, not a finite number"},
        {"mounting_euler_deg = [0, 0, -inf]", "mounting_euler_deg", "-inf",
         "element 2 is -inf, not a finite number"},
        {"mounting_euler_deg = [1e308, 0, 0]", "mounting_euler_deg", "1e308",
         "element 0 is 1e+308, out of range"},
        {"mounting_euler_deg = [0, 360.5, 0]", "mounting_euler_deg", "360.5",
         "element 1 is 360.5, out of range"},
        {"mounting_quat = [nan, 0, 0, 0]", "mounting_quat", "nan",
         "element 0 is nan, not a finite number"},
        {"mounting_quat = [1, 0, 0, inf]", "mounting_quat", "inf",
         "element 3 is inf, not a finite number"},
        {"mounting_quat = [1e308, 1e308, 0, 0]", "mounting_quat", "1e308",
         "element 0 is 1e+308, out of range"},
        {"mounting_quat = [0, 0, 0, 0]", "mounting_quat", "[0", "not a unit quaternion"},
        {"position_m = [nan, 0.05, 0]", "position_m", "nan",
         "element 0 is nan, not a finite number"},
        {"position_m = [0, 0.05, -inf]", "position_m", "-inf",
         "element 2 is -inf, not a finite number"},
        {"position_m = [0, 1e308, 0]", "position_m", "1e308", "element 1 is 1e+308, out of range"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.line);
        const std::string text = kHeader + sensor("a", "pelvis", 0, 0x68, c.line + "\n");
        const auto r = load(text);
        expectOneError(r, "sensor[0]." + c.key, lineOf(text, c.line), c.message);
        if (r.errors.size() != 1) {
            continue;  // reported above
        }
        const auto lineStart = text.find(c.line);
        const auto column = static_cast<int>(text.find(c.element, lineStart) - lineStart) + 1;
        EXPECT_EQ(r.errors[0].where.column, column) << r.errors[0].str();
    }
}

TEST(BoardLoader, AcceptsMountingAndPositionAtTheEdgesOfTheirRanges) {
    const auto r = load(kHeader + sensor("a", "pelvis", 0, 0x68,
                                         "mounting_euler_deg = [-360, 360, 359.5]\n"
                                         "position_m = [-1, 1, 0.0]\n"));
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_EQ(r.board->sensors[0].positionM, Vec3d(-1, 1, 0));
}

// Every single number the loader reads goes through the same check: nan and inf are named as
// such, not reported as a range the reader then has to puzzle over.
TEST(BoardLoader, RejectsANonFiniteNumberWhereverItIs) {
    struct Case {
        std::string from, to, key;
    };
    const std::string base =
        R"(schema = 1
name = "test"

[subject]
height_m = 1.8
mass_kg = 80
[subject.segment_lengths_m]
l_upperarm = 0.31

[[bus]]
name = "i2c1"
type = "i2c"
device = "/dev/i2c-1"
clock_hz = 400000

[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "i2c1"
address = 0x68
odr_hz = 100
mag_odr_hz = 100
accel_range_g = 16
gyro_range_dps = 2000

[display]
type = "none"
fps = 30
)";
    ASSERT_TRUE(load(base).ok()) << load(base).errors[0].str();
    const Case cases[] = {
        {"height_m = 1.8", "height_m = nan", "subject.height_m"},
        {"mass_kg = 80", "mass_kg = inf", "subject.mass_kg"},
        {"l_upperarm = 0.31", "l_upperarm = -nan", "subject.segment_lengths_m.l_upperarm"},
        {"clock_hz = 400000", "clock_hz = inf", "bus[0].clock_hz"},
        {"odr_hz = 100", "odr_hz = nan", "sensor[0].odr_hz"},
        {"mag_odr_hz = 100", "mag_odr_hz = +inf", "sensor[0].mag_odr_hz"},
        {"accel_range_g = 16", "accel_range_g = nan", "sensor[0].accel_range_g"},
        {"gyro_range_dps = 2000", "gyro_range_dps = inf", "sensor[0].gyro_range_dps"},
        {"fps = 30", "fps = nan", "display.fps"},
    };
    for (const Case& c : cases) {
        SCOPED_TRACE(c.to);
        std::string text = base;
        text.replace(text.find(c.from), c.from.size(), c.to);
        const auto r = load(text);
        EXPECT_FALSE(r.ok());
        if (r.errors.empty()) {
            continue;
        }
        // A missing clock or rate may add follow-on errors; the first is the number itself.
        const Diagnostic& d = r.errors[0];
        EXPECT_EQ(d.key, c.key) << d.str();
        EXPECT_EQ(d.where.line, lineOf(text, c.to)) << d.str();
        EXPECT_THAT(d.message, HasSubstr("not a finite number")) << d.str();
    }
}

TEST(BoardLoader, ReportsEveryMistakeNotJustTheFirst) {
    std::string text =
        kHeader + sensor("a", "tail", 0, 0x68, "drdy = \"gpio4\"\n") + sensor("b", "t12", 0, 0x69);
    text.replace(text.find("odr_hz = 100", text.find("name = \"b\"")), 12, "odr_hz = 77");
    const auto r = load(text);
    ASSERT_EQ(r.errors.size(), 3u);
    EXPECT_EQ(r.errors[0].key, "sensor[0].segment");
    EXPECT_EQ(r.errors[1].key, "sensor[0].drdy");
    EXPECT_EQ(r.errors[2].key, "sensor[1].odr_hz");
    for (const auto& e : r.errors) {
        EXPECT_GT(e.where.line, 0);
        EXPECT_THAT(e.str(), ::testing::StartsWith("test.toml:"));
    }
}

TEST(BoardLoader, ReadsTheRuntimeSchedulingOfTheCaptureThreads) {
    const auto r = load(kHeader + sensor("s1", "pelvis", 0, 0x68) +
                        "\n[runtime]\nrealtime_priority = 40\ncpus = [1, 3]\n");
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_EQ(r.board->runtime.realtimePriority, 40);
    EXPECT_EQ(r.board->runtime.cpus, (std::vector<int>{1, 3}));
}

TEST(BoardLoader, WithoutRuntimeTheCaptureThreadsScheduleNormally) {
    const auto r = load(kHeader + sensor("s1", "pelvis", 0, 0x68));
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_EQ(r.board->runtime.realtimePriority, 0);
    EXPECT_TRUE(r.board->runtime.cpus.empty());
}

TEST(BoardLoader, ReportsARealtimePriorityOutOfRange) {
    const std::string text =
        kHeader + sensor("s1", "pelvis", 0, 0x68) + "\n[runtime]\nrealtime_priority = 120\n";
    expectOneError(load(text), "runtime.realtime_priority", lineOf(text, "realtime_priority"),
                   "out of range");
}

TEST(BoardLoader, ReportsACpuListedTwiceAndANegativeCpu) {
    const std::string twice =
        kHeader + sensor("s1", "pelvis", 0, 0x68) + "\n[runtime]\ncpus = [2, 2]\n";
    expectOneError(load(twice), "runtime.cpus", lineOf(twice, "cpus"), "CPU 2 is listed twice");
    const std::string negative =
        kHeader + sensor("s1", "pelvis", 0, 0x68) + "\n[runtime]\ncpus = [0, -1]\n";
    expectOneError(load(negative), "runtime.cpus", lineOf(negative, "cpus"), "CPU numbers");
}

TEST(BoardLoader, ReportsAFileItCannotRead) {
    const auto r = loadBoardFile("/nonexistent/board.toml");
    ASSERT_EQ(r.errors.size(), 1u);
    EXPECT_THAT(r.errors[0].str(), HasSubstr("/nonexistent/board.toml"));
    EXPECT_THAT(r.errors[0].message, HasSubstr("No such file or directory"));
}

TEST(ShippedBoards, SimSuitHas17SensorsCoveringTheBody) {
    const auto r = loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-suit.toml");
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_EQ(r.board->sensors.size(), 17u);
    for (const auto& load : r.loads) {
        EXPECT_LE(load.utilisation, kMaxBusUtilisation);
    }
}

TEST(ShippedBoards, SimUpper10IsThePapersLayout) {
    const auto r = loadBoardFile(CAPHUB_SOURCE_DIR "/board/sim-upper10.toml");
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    ASSERT_EQ(r.board->sensors.size(), 10u);
    std::set<Segment> segs;
    for (const auto& s : r.board->sensors) {
        segs.insert(s.segment);
        EXPECT_EQ(s.achievedOdrHz, 50.0);
    }
    for (Segment s : {Segment::LUpperarm, Segment::RUpperarm, Segment::LForearm, Segment::RForearm,
                      Segment::LHand, Segment::RHand, Segment::Skull}) {
        EXPECT_TRUE(segs.count(s)) << segmentName(s);
    }
}

}  // namespace
}  // namespace caphub::board

namespace caphub::board {
namespace {

// The full example of docs/user-guide.md must stay a valid board file.
TEST(Documentation, UserGuideExampleIsValid) {
    std::ifstream in(CAPHUB_SOURCE_DIR "/docs/user-guide.md");
    ASSERT_TRUE(in);
    std::stringstream doc;
    doc << in.rdbuf();
    const std::string text = doc.str();
    const auto begin = text.find("```toml\n");
    ASSERT_NE(begin, std::string::npos);
    const auto end = text.find("```", begin + 8);
    const auto r = loadBoardText(text.substr(begin + 8, end - begin - 8), "user-guide.md");
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_EQ(r.board->sensors.size(), 2u);
    EXPECT_EQ(r.board->display.type, DisplayType::Framebuffer);
    ASSERT_EQ(r.board->subject.segmentLengthsM.size(), 1u);
}

TEST(ShippedBoards, SparseSuitsNameTheirLayout) {
    const struct {
        const char* file;
        BodyLayout layout;
        std::size_t sensors;
    } boards[] = {
        {"/board/sim-suit.toml", BodyLayout::Full, 17},
        {"/board/sim-upper10.toml", BodyLayout::Upper10, 10},
        {"/board/sim-suit-lower7.toml", BodyLayout::Lower7, 7},
    };
    for (const auto& b : boards) {
        const auto r = loadBoardFile(std::string(CAPHUB_SOURCE_DIR) + b.file);
        ASSERT_TRUE(r.ok()) << r.errors[0].str();
        EXPECT_TRUE(r.warnings.empty()) << r.warnings[0].str();
        ASSERT_TRUE(r.board->body.layout) << b.file;
        EXPECT_EQ(*r.board->body.layout, b.layout) << b.file;
        EXPECT_EQ(r.board->sensors.size(), b.sensors) << b.file;
        std::vector<Segment> segments;
        for (const auto& s : r.board->sensors) {
            segments.push_back(s.segment);
        }
        EXPECT_EQ(matchLayout(segments), b.layout) << b.file;
    }
}

TEST(BoardLoader, ASparseLayoutMustCoverThePelvis) {
    const std::string text = kHeader + "\n[body]\nlayout = \"sparse\"\n" +
                             sensor("a", "t12", 0, 0x68) + sensor("b", "l_thigh", 0, 0x69);
    expectOneError(load(text), "body.layout", lineOf(text, "layout ="),
                   "layout 'sparse' needs a sensor on the pelvis");
    // With it, any subset is a sparse suit.
    const auto ok =
        load(kHeader + "\n[body]\nlayout = \"sparse\"\n" + sensor("p", "pelvis", 1, 0x68) +
             sensor("a", "t12", 0, 0x68) + sensor("b", "l_thigh", 0, 0x69));
    ASSERT_TRUE(ok.ok()) << ok.errors[0].str();
    EXPECT_EQ(ok.board->body.layout, BodyLayout::Sparse);
}

TEST(BoardLoader, ANamedLayoutMustHaveExactlyItsSensors) {
    // lower7 with a chest sensor too, and without the right foot.
    const std::string text = kHeader + "\n[body]\nlayout = \"lower7\"\n" +
                             sensor("p", "pelvis", 0, 0x68) + sensor("c", "t12", 0, 0x69) +
                             sensor("lt", "l_thigh", 1, 0x68) + sensor("ls", "l_calf", 1, 0x69) +
                             sensor("lf", "l_hindfoot", 2, 0x68) +
                             sensor("rt", "r_thigh", 2, 0x69) + sensor("rs", "r_calf", 3, 0x68);
    const auto r = load(text);
    expectOneError(r, "body.layout", lineOf(text, "layout ="), "no sensor on r_hindfoot");
    EXPECT_THAT(r.errors[0].message, HasSubstr("not part of it: t12"));
    EXPECT_THAT(r.errors[0].message, HasSubstr("layout = \"sparse\""));
}

TEST(BoardLoader, AnUnknownLayoutIsNamed) {
    const std::string text =
        kHeader + "\n[body]\nlayout = \"upper9\"\n" + sensor("p", "pelvis", 0, 0x68);
    expectOneError(load(text), "body.layout", lineOf(text, "layout ="),
                   "unknown layout 'upper9' (expected \"full\", \"upper10\", \"lower7\" or "
                   "\"sparse\")");
}

TEST(BoardLoader, ABoardWithoutALayoutOrAPelvisSensorLoadsWithAWarning) {
    // A bench board: a sensor or two anywhere. It loads, and says what a body would lack.
    const auto r = load(kHeader + sensor("a", "l_hand", 0, 0x68));
    ASSERT_TRUE(r.ok()) << r.errors[0].str();
    EXPECT_FALSE(r.board->body.layout);
    ASSERT_EQ(r.warnings.size(), 1u);
    EXPECT_EQ(r.warnings[0].key, "body");
    EXPECT_THAT(r.warnings[0].message, HasSubstr("no sensor on the pelvis"));
    EXPECT_TRUE(load(kHeader + sensor("a", "pelvis", 0, 0x68)).warnings.empty());
}

}  // namespace
}  // namespace caphub::board
