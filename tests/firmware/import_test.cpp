// caphub import of Xsens MT Manager text exports: the files' samples, orientations and packet
// gaps into a .cap that `caphub info` reads, and malformed input reported as file:line:column.
// And of caphub's own BROAD-layout streams (`caphub sim --all`): raw samples, caphub's filter's
// orientations and poses, gaps, malformed input.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include "firmware/io/broad_csv.h"
#include "firmware/io/xsens_text.h"
#include "firmware/recording/reader.h"
#include "tests/firmware/cli_run.h"

namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using caphub::testing::caphub;
using caphub::testing::CliRun;

const std::string kShank =
    std::string(CAPHUB_TEST_DATA_DIR) + "/xsens/MT_012005D6_031-000_00B421AF.txt";
const std::string kThigh =
    std::string(CAPHUB_TEST_DATA_DIR) + "/xsens/MT_012005D6_031-000_00B4227B.txt";

std::string temp(const std::string& name) {
    const std::string d = ::testing::TempDir() + "caphub_import_" + std::to_string(getpid());
    fs::create_directories(d);
    return d + "/" + name;
}

std::string readAll(const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
}

std::vector<std::string> lines(const std::string& text) {
    std::vector<std::string> out;
    std::istringstream in(text);
    std::string l;
    while (std::getline(in, l)) {
        out.push_back(l);
    }
    return out;
}

std::string writeLines(const std::string& name, const std::vector<std::string>& ls) {
    const std::string p = temp(name);
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    for (const auto& l : ls) {
        out << l << "\n";
    }
    return p;
}

std::string mapFile() {
    const std::string p = temp("map.toml");
    std::ofstream(p) << "height_m = 1.80\n[sensors]\n00B421AF = \"r_calf\"\n"
                        "00B4227B = \"r_thigh\"\n";
    return p;
}

TEST(XsensText, ReadsTheSamplesTheRateAndTheOrientationMatrix) {
    auto f = caphub::firmware::readXsensText(kShank);
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->deviceId, "00B421AF");
    EXPECT_DOUBLE_EQ(f->rateHz, 100.0);
    EXPECT_EQ(f->separator, '\t');
    ASSERT_EQ(f->samples.size(), 300u);
    EXPECT_EQ(f->firstCounter, 3583);
    EXPECT_EQ(f->samples.back().packet, 299);
    EXPECT_EQ(f->lostPackets, 0);
    EXPECT_EQ(f->orientationColumns, "matrix");
    // The first row: Acc 3.030769 5.254238 -7.714005, Gyr 0.005991 -0.032133 0.022713.
    const auto& s = f->samples.front();
    EXPECT_DOUBLE_EQ(s.accMps2.x(), 3.030769);
    EXPECT_DOUBLE_EQ(s.accMps2.z(), -7.714005);
    EXPECT_DOUBLE_EQ(s.gyrRadps.y(), -0.032133);
    ASSERT_TRUE(s.mag.has_value());
    EXPECT_DOUBLE_EQ(s.mag->z(), 0.897217);
    // Mat[r][c] is the rotation sensor -> earth: its third row takes the accelerometer's
    // reading at rest to +g up (the leg is still at the start); 6 decimals in the file.
    ASSERT_TRUE(s.qEarthSensor.has_value());
    const Eigen::Vector3d up = *s.qEarthSensor * s.accMps2;
    EXPECT_NEAR(up.z(), s.accMps2.norm(), 0.01);
    EXPECT_NEAR(up.head<2>().norm(), 0.0, 0.1);
}

TEST(XsensText, CommasAndQuaternionColumnsAreReadToo) {
    auto f = caphub::firmware::readXsensText(
        writeLines("MT_X_00000001.txt",
                   {"// Update Rate: 60.0Hz",
                    "PacketCounter,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,"
                    "Quat_q0,Quat_q1,Quat_q2,Quat_q3",
                    "65534,0,0,9.81,0,0,0,1,0,0,0", "65535,0,0,9.81,0,0,0,0.7071068,0,0,0.7071068",
                    "1,0,0,9.81,0,0,0,1,0,0,0"}));
    ASSERT_TRUE(f.ok()) << f.error().message;
    EXPECT_EQ(f->deviceId, "00000001");
    EXPECT_EQ(f->separator, ',');
    EXPECT_EQ(f->orientationColumns, "quaternion");
    EXPECT_FALSE(f->hasMag);
    ASSERT_EQ(f->samples.size(), 3u);
    EXPECT_NEAR(f->samples[1].qEarthSensor->z(), 0.7071068, 1e-6);  // normalised
    // The counter wraps at 16 bits: 65535 -> 1 loses packet 0.
    EXPECT_EQ(f->samples[2].packet, 3);
    EXPECT_EQ(f->lostPackets, 1);
    ASSERT_EQ(f->gaps.size(), 1u);
    EXPECT_EQ(f->gaps[0].line, 5);
}

// A file with both forms of the vendor's orientation: they are one orientation, or the file is
// refused at the row where they part (an attacker's file took the quaternion silently).
TEST(XsensText, AQuaternionAndAMatrixOnOneRowMustAgree) {
    const std::string header =
        "PacketCounter,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,Gyr_Z,Quat_q0,Quat_q1,Quat_q2,Quat_q3,"
        "Mat[1][1],Mat[2][1],Mat[3][1],Mat[1][2],Mat[2][2],Mat[3][2],Mat[1][3],Mat[2][3],"
        "Mat[3][3]";
    // 90 deg about z: q = (0.7071068, 0, 0, 0.7071068), R columns (0 1 0) (-1 0 0) (0 0 1).
    const std::string turned = "0,0,9.81,0,0,0,0.7071068,0,0,0.7071068,0,1,0,-1,0,0,0,0,1";
    auto both = caphub::firmware::readXsensText(writeLines(
        "MT_Both_00000002.txt", {"// Update Rate: 60.0Hz", header,
                                 "1,0,0,9.81,0,0,0,1,0,0,0,1,0,0,0,1,0,0,0,1", "2," + turned}));
    ASSERT_TRUE(both.ok()) << both.error().message;
    EXPECT_EQ(both->orientationColumns, "quaternion and matrix");
    ASSERT_EQ(both->samples.size(), 2u);
    EXPECT_NEAR(both->samples[1].qEarthSensor->z(), 0.7071068, 1e-6);

    // The matrix of the identity beside the quaternion of the turn: 90 deg apart.
    const std::string apart = "3,0,0,9.81,0,0,0,0.7071068,0,0,0.7071068,1,0,0,0,1,0,0,0,1";
    const std::string p = writeLines("MT_Apart_00000002.txt",
                                     {"// Update Rate: 60.0Hz", header, "2," + turned, apart});
    auto refused = caphub::firmware::readXsensText(p);
    ASSERT_FALSE(refused.ok());
    EXPECT_THAT(refused.error().message,
                HasSubstr(p + ":4:" + std::to_string(apart.find(",1,0,0,0,1") + 2) +
                          ": Mat[r][c] is 90.00 deg from Quat_q0..q3 on the same row"));
}

TEST(XsensText, MalformedInputNamesFileLineAndColumn) {
    auto rows = lines(readAll(kShank));
    rows.resize(12);
    // Line 9: the 16th cell (Acc_Y) replaced by a word.
    auto bad = rows;
    {
        std::string& l = bad[8];
        std::size_t at = 0;
        for (int tab = 0; tab < 15; ++tab) {
            at = l.find('\t', at) + 1;
        }
        const std::size_t end = l.find('\t', at);
        l.replace(at, end - at, "oops");
        const std::string p = writeLines("MT_bad_00B421AF.txt", bad);
        auto f = caphub::firmware::readXsensText(p);
        ASSERT_FALSE(f.ok());
        EXPECT_EQ(f.error().message,
                  p + ":9:" + std::to_string(at + 1) + ": Acc_Y: expected a number, found 'oops'");
    }
    // A row with a cell missing.
    auto shortRow = rows;
    shortRow[10] = shortRow[10].substr(0, shortRow[10].rfind('\t'));
    const std::string ps = writeLines("MT_short_00B421AF.txt", shortRow);
    auto s = caphub::firmware::readXsensText(ps);
    ASSERT_FALSE(s.ok());
    EXPECT_THAT(s.error().message, HasSubstr(ps + ":11:1: expected 32 cells as in the header, "
                                                  "found 31"));
    // A repeated packet.
    auto repeated = rows;
    repeated[9] = repeated[8];
    const std::string pr = writeLines("MT_rep_00B421AF.txt", repeated);
    auto r = caphub::firmware::readXsensText(pr);
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr(pr + ":10:1: PacketCounter 3585 after 3585"));
    // No rate line.
    auto noRate = rows;
    noRate.erase(noRate.begin() + 1);
    const std::string pn = writeLines("MT_norate_00B421AF.txt", noRate);
    auto n = caphub::firmware::readXsensText(pn);
    ASSERT_FALSE(n.ok());
    EXPECT_THAT(n.error().message, HasSubstr(pn + ":5:1: no '// Update Rate: ...Hz' line"));
    // A missing required column.
    auto noGyr = rows;
    noGyr[5].replace(noGyr[5].find("Gyr_Z"), 5, "Gyr_W");
    const std::string pg = writeLines("MT_nogyr_00B421AF.txt", noGyr);
    auto g = caphub::firmware::readXsensText(pg);
    ASSERT_FALSE(g.ok());
    EXPECT_THAT(g.error().message, HasSubstr(pg + ":6:1: the header has no Gyr_Z column"));
}

// A reading past any sensor's range (1e39 was accepted and became an infinite float in the
// recording) is refused with its cell.
TEST(XsensText, AValueNoSampleCanHoldIsRefusedWithItsCell) {
    auto rows = lines(readAll(kShank));
    rows.resize(12);
    std::string& l = rows[8];
    std::size_t at = 0;
    for (int tab = 0; tab < 15; ++tab) {
        at = l.find('\t', at) + 1;
    }
    l.replace(at, l.find('\t', at) - at, "1e39");
    const std::string p = writeLines("MT_huge_00B421AF.txt", rows);
    auto f = caphub::firmware::readXsensText(p);
    ASSERT_FALSE(f.ok());
    EXPECT_EQ(f.error().message, p + ":9:" + std::to_string(at + 1) +
                                     ": Acc_Y: 1e39 is out of range (at most 1e+06 either way)");
}

// The rate line read leniently gave wrong sample times: "59,94Hz" was 59 Hz, a second rate line
// won silently, 0.5 Hz was found only by the board made from it ("imported board:21:10", exit
// 1); a column given twice used the first silently; a device id that cannot name a sensor broke
// the generated board's TOML.
TEST(XsensText, AmbiguousRatesColumnsAndDeviceIdsAreRefusedWhereTheyAre) {
    auto rows = lines(readAll(kShank));
    rows.resize(12);
    ASSERT_NE(rows[1].find("Update Rate: 100.0Hz"), std::string::npos) << rows[1];
    const auto refused = [&](const std::string& name, const std::vector<std::string>& r,
                             const std::string& says) {
        const std::string p = writeLines(name, r);
        auto f = caphub::firmware::readXsensText(p);
        ASSERT_FALSE(f.ok()) << name;
        EXPECT_THAT(f.error().message, HasSubstr(p + says)) << name;
    };
    const std::size_t at = rows[1].find("Update Rate:");
    const std::string column = ":2:" + std::to_string(at + 14);
    auto comma = rows;
    comma[1].replace(comma[1].find("100.0Hz"), 7, "59,94Hz");
    refused("MT_comma_00B421AF.txt", comma, column + ": Update Rate: expected a rate of 1 to");
    auto slow = rows;
    slow[1].replace(slow[1].find("100.0Hz"), 7, "0.5Hz");
    refused("MT_slow_00B421AF.txt", slow, column + ": Update Rate: expected a rate of 1 to");
    auto twice = rows;
    twice.insert(twice.begin() + 2, "// Update Rate: 7.0Hz");
    refused("MT_twice_00B421AF.txt", twice,
            ":3:" + std::to_string(twice[2].find("Update") + 1) +
                ": a second Update Rate (7 Hz after 100 Hz)");
    auto same = rows;
    same.insert(same.begin() + 2, "// Update Rate: 100.0Hz");
    EXPECT_TRUE(caphub::firmware::readXsensText(writeLines("MT_same_00B421AF.txt", same)).ok());

    auto dup = rows;
    std::string& header = dup[5];
    const std::size_t acc = header.find("Acc_X");
    ASSERT_NE(acc, std::string::npos);
    header.replace(header.find("Acc_Y"), 5, "Acc_X");
    refused("MT_dup_00B421AF.txt", dup,
            ":6:" + std::to_string(header.find("Acc_X", acc + 1) + 1) + ": a second Acc_X column");

    auto good = caphub::firmware::readXsensText(writeLines("MT_x_00B4\"21AF.txt", rows));
    ASSERT_FALSE(good.ok());
    EXPECT_THAT(good.error().message, HasSubstr("the Xsens device name '00B4\"21AF'"));
}

// A 2 kHz take (an MTi-600's rate) was refused by the bus budget of the board the import makes
// for itself, whose buses are simulated: they have no clock now.
TEST(ImportCli, AnXsensTakeAtTwoKilohertzImports) {
    std::string text = readAll(kShank);
    const std::string from = "Update Rate: 100.0Hz";
    ASSERT_NE(text.find(from), std::string::npos);
    text.replace(text.find(from), from.size(), "Update Rate: 2000.0Hz");
    const std::string p = temp("fast_" + fs::path(kShank).filename().string());
    std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
    const std::string map = temp("map1.toml");
    std::ofstream(map) << "height_m = 1.80\n[sensors]\n00B421AF = \"r_calf\"\n";
    const std::string out = temp("fast.cap");
    fs::remove(out);
    const CliRun r = caphub("import " + p + " --map " + map + " -o " + out);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("at 2000 Hz on r_calf"));
}

// Xsens MTw run at 40, 60, 80 or 120 Hz too: the imported board's sensors take any rate (they
// used to be ICM-20948s, which cannot run at 60 Hz, and the import failed on its own board).
TEST(ImportCli, AnXsensTakeAtSixtyHertzImportsAndReprocesses) {
    std::vector<std::string> files;
    for (const std::string& src : {kShank, kThigh}) {
        std::string text = readAll(src);
        const std::string from = "Update Rate: 100.0Hz";
        ASSERT_NE(text.find(from), std::string::npos);
        text.replace(text.find(from), from.size(), "Update Rate: 60.0Hz");
        const std::string p = temp("at60_" + fs::path(src).filename().string());
        std::ofstream(p, std::ios::binary | std::ios::trunc) << text;
        files.push_back(p);
    }
    const std::string out = temp("at60.cap");
    fs::remove(out);
    const CliRun r =
        caphub("import " + files[0] + " " + files[1] + " --map " + mapFile() + " -o " + out);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("300 samples at 60 Hz on r_calf"));
    EXPECT_THAT(r.output, HasSubstr("poses: "));
    const std::string again = temp("at60_re.cap");
    fs::remove(again);
    const CliRun re = caphub("reprocess " + out + " -o " + again);
    EXPECT_EQ(re.exitCode, 0) << re.output;
    // The import's own calibration, in the pose held from the first sample: redone there (it
    // was looked for after the capture's 2.5 s of settling, and a 5 s take had no poses).
    EXPECT_THAT(re.output, HasSubstr("the recording's: N-pose held from 0.000 s"));
    EXPECT_THAT(re.output, ::testing::ContainsRegex("orientations, [1-9][0-9]* poses at 60 Hz"));
}

// The shipped excerpt of the two MTw on one leg, with 5 packets of the thigh's taken out: every
// sample is in the .cap, the gap is an event pair, and info describes it.
TEST(ImportCli, TwoXsensSensorsBecomeARecordingThatInfoDescribes) {
    auto thigh = lines(readAll(kThigh));
    thigh.erase(thigh.begin() + 6 + 100, thigh.begin() + 6 + 105);  // packets 3683-3687
    const std::string thighWithGap = writeLines("MT_012005D6_031-000_00B4227B.txt", thigh);
    const std::string out = temp("leg.cap");
    fs::remove(out);
    const CliRun r =
        caphub("import " + kShank + " " + thighWithGap + " --map " + mapFile() + " -o " + out);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("00B421AF (" + kShank +
                                    "): 300 samples at 100 Hz on r_calf, 0 lost in 0 gap(s), "
                                    "orientation (matrix)"));
    EXPECT_THAT(r.output, HasSubstr("295 samples at 100 Hz on r_thigh, 5 lost in 1 gap(s)"));

    auto reader = caphub::firmware::RecordingReader::open(out);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    int raw[2] = {0, 0};
    int orientations = 0;
    caphub::firmware::RecordView v;
    caphub::Timestamp firstThigh{};
    caphub::Timestamp lastThigh{};
    while ((*reader)->next(v) == 1) {
        int sensor = -1;
        caphub::hal::ImuSample s;
        if (caphub::firmware::decodeRawSample(v, sensor, s)) {
            ASSERT_TRUE(sensor == 0 || sensor == 1);
            if (sensor == 1) {
                if (raw[1] == 0) {
                    firstThigh = s.t;
                }
                lastThigh = s.t;
                EXPECT_TRUE(s.flags & caphub::hal::ImuSample::kMagFresh);
                EXPECT_NEAR(s.magUt.norm(), 50.0, 10.0);  // normalised units x 50 uT
            }
            ++raw[sensor];
        }
        orientations += v.type == caphub::firmware::cap::RecordType::Orientation ? 1 : 0;
    }
    EXPECT_EQ(raw[0], 300);
    EXPECT_EQ(raw[1], 295);
    EXPECT_EQ(orientations, 595);
    // Packets 3583..3882 at 100 Hz: the gap keeps the time base.
    EXPECT_EQ(caphub::toNs(lastThigh - firstThigh), 2'990'000'000);

    const CliRun info = caphub("info " + out);
    ASSERT_EQ(info.exitCode, 0) << info.output;
    EXPECT_THAT(info.output, HasSubstr("raw sample   595"));
    EXPECT_THAT(info.output, HasSubstr("segments = [\"r_calf\", \"r_thigh\"]"));
    EXPECT_THAT(info.output, HasSubstr("lost_samples = 5"));
    EXPECT_THAT(info.output, HasSubstr("sensor lost  sensor 1: 5 packet(s) missing in " +
                                       thighWithGap + " before line 107"));
}

// MT Manager's readings are calibrated (the magnetometer's normalised to the local field): the
// import records a calibration that says so. Without it a reprocess took each magnetometer as
// raw and one sensor's heading as unknown at the body calibration, its mounting from the nominal
// heading: on the shared 34 s take the reprocessed knee peaked at 85 deg where the vendor's
// orientations give 70 (the two sensors' tilts agreeing within 3 deg); with it, 74.
TEST(ImportCli, AReprocessedXsensTakeTakesTheVendorsMagnetometersAsCalibrated) {
    const std::string out = temp("vendor-calibrated.cap");
    const std::string again = temp("vendor-calibrated-again.cap");
    fs::remove(out);
    fs::remove(again);
    ASSERT_EQ(
        caphub("import " + kShank + " " + kThigh + " --map " + mapFile() + " -o " + out).exitCode,
        0);
    const CliRun info = caphub("info " + out);
    EXPECT_THAT(info.output, HasSubstr("[calibration]"));
    EXPECT_THAT(info.output, HasSubstr("the vendor's: the files' readings are calibrated"));
    const CliRun re = caphub("reprocess " + out + " -o " + again);
    ASSERT_EQ(re.exitCode, 0) << re.output;
    const CliRun events = caphub("info " + again);
    EXPECT_THAT(events.output, HasSubstr("body calibration: npose pose, 2 segments\n"))
        << events.output;
    EXPECT_THAT(events.output, ::testing::Not(HasSubstr("free heading"))) << events.output;
}

// Poses from the vendor's orientations after an N-pose calibration over the first second (the
// leg stands still at the start of the take): export and replay take the imported take.
TEST(ImportCli, AnImportedTakeHasPosesThatExportAndReplayTake) {
    const std::string out = temp("posed.cap");
    fs::remove(out);
    const CliRun r = caphub("import " + kShank + " " + kThigh + " --map " + mapFile() + " -o " +
                            out + " --pose-rate 50");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("body calibration: npose pose at 1.000 s"));
    // 3 s of samples, the first second for the calibration: 2 s of poses at 50 Hz.
    std::smatch m;
    ASSERT_TRUE(std::regex_search(r.output, m, std::regex(R"(poses: (\d+) at 50 Hz)"))) << r.output;
    EXPECT_NEAR(std::stoi(m[1]), 100, 2);

    const std::string sto = temp("posed.sto");
    const CliRun ex = caphub("export " + out + " --format sto --names opensim -o " + sto);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    EXPECT_EQ(lines(readAll(sto))[5], "time\ttibia_r_imu\tfemur_r_imu");

    // The segments, standing still in the N-pose they were calibrated in: the knee (thigh to
    // shank) straight within 2 deg (0.4 deg measured on this take).
    const std::string segments = temp("posed-segments.sto");
    ASSERT_EQ(caphub("export " + out + " --format sto --names opensim --orientations segments -o " +
                     segments)
                  .exitCode,
              0);
    const auto rows = lines(readAll(segments));
    ASSERT_GT(rows.size(), 7u);
    const auto header = rows[5];
    const auto cellsOf = [](const std::string& row) {
        std::vector<std::string> c;
        std::istringstream in(row);
        std::string cell;
        while (std::getline(in, cell, '\t')) {
            c.push_back(cell);
        }
        return c;
    };
    const auto names = cellsOf(header);
    const auto values = cellsOf(rows[6]);
    const auto quat = [&](const std::string& label) {
        const auto at = std::find(names.begin(), names.end(), label) - names.begin();
        double w = 0, x = 0, y = 0, z = 0;
        char comma = 0;
        std::istringstream(values[static_cast<std::size_t>(at)]) >> w >> comma >> x >> comma >> y >>
            comma >> z;
        return Eigen::Quaterniond(w, x, y, z).normalized();
    };
    const double kneeDeg = quat("femur_r_imu").angularDistance(quat("tibia_r_imu")) * 180 / M_PI;
    EXPECT_LT(kneeDeg, 2.0);

    const CliRun bvh = caphub("export " + out + " --format bvh -o " + temp("posed.bvh"));
    EXPECT_EQ(bvh.exitCode, 0) << bvh.output;
    const CliRun replay =
        caphub("replay " + out + " --preview png:" + temp("frames") + " --speed 0 --fps 5");
    EXPECT_EQ(replay.exitCode, 0) << replay.output;
    EXPECT_TRUE(fs::exists(temp("frames") + "/frame_000000.png"));
}

TEST(ImportCli, BadMapsAndUnmappedSensorsAreUsageErrors) {
    const std::string out = temp("bad.cap");
    const std::string onlyShank = temp("only-shank.toml");
    std::ofstream(onlyShank) << "[sensors]\n00B421AF = \"r_calf\"\n";
    CliRun r = caphub("import " + kShank + " " + kThigh + " --map " + onlyShank + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("sensor 00B4227B has no segment in " + onlyShank));

    const std::string badSegment = temp("bad-segment.toml");
    std::ofstream(badSegment) << "height_m = 1.8\n[sensors]\n00B421AF = \"shin\"\n";
    r = caphub("import " + kShank + " --map " + badSegment + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr(badSegment + ":3:12: sensors.00B421AF: expected a segment"));

    const std::string twice = temp("twice.toml");
    std::ofstream(twice) << "[sensors]\n00B421AF = \"r_calf\"\n00B4227B = \"r_calf\"\n";
    r = caphub("import " + kShank + " --map " + twice + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr("segment 'r_calf' is already sensor 00B421AF's"));
    EXPECT_FALSE(fs::exists(out));

    // An existing file is not overwritten.
    std::ofstream(out) << "keep";
    r = caphub("import " + kShank + " --map " + mapFile() + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_EQ(readAll(out), "keep");
}

// `caphub sim --all` on the 10-sensor upper body (ideal chips, the shipped walk) once for the
// BROAD tests: the folder of streams.
const std::string& simulatedStreams() {
    static const std::string dir = [] {
        const std::string d = temp("sim-upper10");
        fs::remove_all(d);
        const CliRun r =
            caphub("sim --board sim-upper10 --all --profile ideal --seed 3 --out " + d);
        EXPECT_EQ(r.exitCode, 0) << r.output;
        return d;
    }();
    return dir;
}

TEST(ImportBroadCli, SimulatedStreamsBecomeARecordingWithCaphubsOrientationsAndPoses) {
    const std::string dir = simulatedStreams();
    const std::string out = temp("broad.cap");
    fs::remove(out);
    const CliRun r = caphub("import " + dir + " -o " + out);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    // The sensors' names and segments come from the files' comment lines, the nominal mountings
    // from the board they name.
    EXPECT_THAT(r.output, HasSubstr("pelvis (" + dir + "/pelvis.csv.gz): "));
    EXPECT_THAT(r.output, HasSubstr("on l_upperarm, 0 lost in 0 gap(s)"));
    EXPECT_THAT(r.output, HasSubstr(": 10 sensors, "));
    EXPECT_THAT(r.output, HasSubstr("mountings and positions from board 'sim-upper10'"));
    EXPECT_THAT(r.output, HasSubstr("body calibration: none"));

    // Every row is a raw sample of the recording, at the file's time; the filter's orientations
    // follow the truth the files carry in inclination once the filter has settled (a swapped
    // axis, a wrong frame or time would put them tens of degrees off). Not in heading: without
    // a magnetometer calibration the filters hold a gyroscope-only heading until their online
    // hard-iron estimate is good (docs/fusion.md), and the body calibration absorbs the offset.
    // Measured (mean after 1 s, ideal chips, seed 3): pelvis 2.5, chest 3.2, head 2.7, waist 5.6
    // deg; the swinging arms 11-16 deg (docs/import.md).
    std::vector<caphub::firmware::BroadTrial> trials;
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir)) {
        const std::string n = e.path().filename().string();
        if (n != "skeleton.csv.gz") {
            names.push_back(n);
        }
    }
    std::sort(names.begin(), names.end());
    std::size_t rows = 0;
    for (const auto& n : names) {
        auto t = caphub::firmware::readBroadCsv(dir + "/" + n);
        ASSERT_TRUE(t) << t.error().message;
        rows += t->samples.size();
        trials.push_back(std::move(*t));
    }
    ASSERT_EQ(trials.size(), 10u);
    auto reader = caphub::firmware::RecordingReader::open(out);
    ASSERT_TRUE(reader.ok()) << reader.error().message;
    std::size_t raw = 0;
    std::size_t poses = 0;
    std::vector<std::size_t> seen(trials.size(), 0);
    std::vector<double> errSum(trials.size(), 0.0);
    std::vector<int> errCount(trials.size(), 0);
    caphub::firmware::RecordView v;
    while ((*reader)->next(v) == 1) {
        int sensor = -1;
        caphub::hal::ImuSample s;
        Eigen::Quaternionf q;
        if (caphub::firmware::decodeRawSample(v, sensor, s)) {
            ASSERT_GE(sensor, 0);
            ASSERT_LT(sensor, 10);
            const auto& trial = trials[static_cast<std::size_t>(sensor)];
            const auto k = seen[static_cast<std::size_t>(sensor)]++;
            ASSERT_LT(k, trial.samples.size());
            EXPECT_NEAR(caphub::toSeconds(s.t.time_since_epoch()) - 1.0, trial.samples[k].tS, 1e-6);
            EXPECT_NEAR(s.accMps2.x(), trial.samples[k].accMps2.x(), 1e-4);
            ++raw;
        } else if (caphub::firmware::decodeOrientation(v, sensor, q)) {
            const auto u = static_cast<std::size_t>(sensor);
            const auto& trial = trials[u];
            const double tS = caphub::toSeconds(v.t.time_since_epoch()) - 1.0;
            // The row of the orientation's time.
            const auto row = std::lower_bound(trial.samples.begin(), trial.samples.end(), tS - 1e-6,
                                              [](const auto& a, double t) { return a.tS < t; });
            ASSERT_NE(row, trial.samples.end());
            ASSERT_NEAR(row->tS, tS, 1e-6);
            if (tS > 1.0) {
                const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();  // ENU
                const Eigen::Vector3d solved = q.cast<double>().conjugate() * up;
                const Eigen::Vector3d want =
                    trial.truth[static_cast<std::size_t>(row - trial.samples.begin())].conjugate() *
                    up;
                errSum[u] += std::acos(std::clamp(solved.dot(want), -1.0, 1.0)) * 180 / M_PI;
                ++errCount[u];
            }
        } else if (v.type == caphub::firmware::cap::RecordType::Pose) {
            ++poses;
        }
    }
    EXPECT_EQ(raw, rows);
    std::string errors;
    for (std::size_t i = 0; i < trials.size(); ++i) {
        errors += fmt::format("{} {:.2f} deg; ", names[i], errSum[i] / errCount[i]);
    }
    for (std::size_t i = 0; i < trials.size(); ++i) {
        ASSERT_GT(errCount[i], 100);
        const bool trunk = names[i] == "pelvis.csv.gz" || names[i] == "waist.csv.gz" ||
                           names[i] == "chest.csv.gz" || names[i] == "head.csv.gz";
        EXPECT_LT(errSum[i] / errCount[i], trunk ? 8.0 : 25.0) << errors;
    }
    // One pose per grid point over the take at 60 Hz.
    EXPECT_NEAR(static_cast<double>(poses),
                (trials[0].samples.back().tS - trials[0].samples.front().tS) * 60, 3);

    const CliRun info = caphub("info " + out);
    ASSERT_EQ(info.exitCode, 0) << info.output;
    EXPECT_THAT(info.output, HasSubstr(fmt::format("raw sample   {}", rows)));
    EXPECT_THAT(info.output, HasSubstr("name = \"imported-broad\""));

    // The tools take it: reprocess (smoothed), export, replay.
    const std::string again = temp("broad-smooth.cap");
    fs::remove(again);
    const CliRun re = caphub("reprocess " + out + " -o " + again + " --smooth");
    EXPECT_EQ(re.exitCode, 0) << re.output;
    const std::string csv = temp("broad.csv");
    const CliRun ex = caphub("export " + out + " --format csv -o " + csv);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    // The legs of the upper body are held, not measured, in every row.
    const auto csvRows = lines(readAll(csv));
    ASSERT_GT(csvRows.size(), 100u);
    EXPECT_TRUE(csvRows[50].ends_with(
        ",l_thigh l_calf l_hindfoot l_middistal r_thigh r_calf r_hindfoot r_middistal"))
        << csvRows[50];
    const CliRun replay =
        caphub("replay " + out + " --preview png:" + temp("broad-frames") + " --speed 0 --fps 2");
    EXPECT_EQ(replay.exitCode, 0) << replay.output;
}

TEST(ImportBroadCli, AGapIsRecordedAsTheSensorLostAndBack) {
    const std::string dir = temp("gap");
    fs::remove_all(dir);
    fs::create_directories(dir);
    // The pelvis stream with rows 101-110 taken out (0.2 s at 50 Hz), written plain.
    auto t = caphub::firmware::readBroadCsv(simulatedStreams() + "/pelvis.csv.gz");
    ASSERT_TRUE(t) << t.error().message;
    t->samples.erase(t->samples.begin() + 100, t->samples.begin() + 110);
    t->truth.erase(t->truth.begin() + 100, t->truth.begin() + 110);
    t->movement.erase(t->movement.begin() + 100, t->movement.begin() + 110);
    ASSERT_TRUE(caphub::firmware::writeBroadCsv(dir + "/pelvis.csv", *t));
    fs::copy_file(simulatedStreams() + "/chest.csv.gz", dir + "/chest.csv.gz");
    const std::string out = temp("gap.cap");
    fs::remove(out);
    const CliRun r = caphub("import " + dir + "/pelvis.csv " + dir + "/chest.csv.gz -o " + out);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("on pelvis, 10 lost in 1 gap(s)"));
    const CliRun info = caphub("info " + out);
    ASSERT_EQ(info.exitCode, 0) << info.output;
    EXPECT_THAT(info.output, HasSubstr("lost_samples = 10"));
    EXPECT_THAT(info.output, HasSubstr("sensor lost  sensor 0: 0.220 s without samples in " + dir +
                                       "/pelvis.csv"));
}

TEST(ImportBroadCli, MalformedStreamsNameFileLineAndColumn) {
    const std::string dir = temp("bad-broad");
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string out = temp("bad-broad.cap");
    fs::remove(out);
    const std::string header = "t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,mag_x,mag_y,mag_z";
    // A cell that is not a number: line 4, where it starts.
    const std::string bad =
        writeLines("bad-broad/bad.csv",
                   {"# BROAD trial caphub-sim walk sensor pelvis on pelvis "
                    "(board sim-upper10, profile ideal, seed 1); "
                    "sampling_rate_hz=50",
                    header, "0.00,0,0,0,0,0,9.8,0,20,-40", "0.02,0,0,0,0,oops,9.8,0,20,-40"});
    CliRun r = caphub("import " + bad + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr(bad + ":4:14: field 'acc_y': expected a finite number, got "
                                          "'oops'"));
    EXPECT_FALSE(fs::exists(out));

    // A stream without the comment line of `caphub sim` has no segment: --map gives it.
    const std::string plain = writeLines(
        "bad-broad/l_foot.csv", {header, "0.00,0,0,0,0,0,9.8,0,20,-40",
                                 "0.01,0,0,0,0,0,9.8,0,20,-40", "0.02,0,0,0,0,0,9.8,0,20,-40"});
    r = caphub("import " + plain + " -o " + out);
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr(plain + ":1:1: sensor 'l_foot': no segment"));
    EXPECT_THAT(r.output, HasSubstr("give --map"));
    const std::string map = temp("bad-broad-map.toml");
    std::ofstream(map) << "[sensors]\nl_foot = \"l_hindfoot\"\n";
    r = caphub("import " + plain + " --map " + map + " -o " + out);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_THAT(r.output, HasSubstr("3 samples at 100 Hz on l_hindfoot"));
    EXPECT_THAT(r.output, HasSubstr("no board named: identity nominal mountings"));

    // Two files on one segment; a folder with no streams.
    const std::string other =
        writeLines("bad-broad/other.csv",
                   {header, "0.00,0,0,0,0,0,9.8,0,20,-40", "0.01,0,0,0,0,0,9.8,0,20,-40"});
    std::ofstream(map) << "[sensors]\nl_foot = \"l_hindfoot\"\nother = \"l_hindfoot\"\n";
    r = caphub("import " + plain + " " + other + " --map " + map + " -o " + temp("two.cap"));
    EXPECT_EQ(r.exitCode, 2) << r.output;
    const std::string empty = temp("empty-dir");
    fs::create_directories(empty);
    r = caphub("import " + empty + " -o " + temp("empty.cap"));
    EXPECT_EQ(r.exitCode, 2) << r.output;
    EXPECT_THAT(r.output, HasSubstr(empty + ": a folder with no .csv or .csv.gz stream"));
}

}  // namespace
