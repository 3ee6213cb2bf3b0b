// The bus budget: wire time per transaction and what a board's sensors cost each bus.
#include "board/bus_budget.h"

#include <gtest/gtest.h>

#include "board/loader.h"

namespace caphub::board {
namespace {

TEST(BusBudget, I2cRegisterReadBitsCountEveryByteAndCondition) {
    // S + (addr+W, reg, addr+R) with ACKs + 23 data bytes with ACK/NACK + Sr + P.
    EXPECT_EQ(i2cRegisterReadBits(23), 1 + 27 + 1 + 23 * 9 + 1);
    EXPECT_EQ(i2cWriteBits(1), 1 + 9 + 9 + 1);
    EXPECT_EQ(spiRegisterReadBits(23), 8 * 24);
}

TEST(BusBudget, OneIcm20948BurstAt400kHzIsWithinTheArchitecturesEstimate) {
    // docs: one block read per sensor per sample at 400 kHz costs ~0.3-0.8 ms.
    const double ms = i2cRegisterReadBits(23) / 400e3 * 1e3;
    EXPECT_GT(ms, 0.3);
    EXPECT_LT(ms, 0.8);
}

Board twoSensorBoard(bool withMux, bool withDrdy) {
    const std::string text =
        std::string(R"(schema = 1
name = "t"
[[bus]]
name = "b"
type = "sim"
clock_hz = 400000
[[mux]]
name = "m"
bus = "b"
address = 0x70
[[sensor]]
name = "a"
segment = "pelvis"
chip = "icm20948"
bus = "b"
)") + (withMux ? "mux = \"m\"\nchannel = 0\n" : "") +
        "address = 0x68\nodr_hz = 100\n" + (withDrdy ? "drdy = \"gpiochip0:1\"\n" : "") + R"(
[[sensor]]
name = "c"
segment = "t12"
chip = "icm20948"
bus = "b"
)" + (withMux ? "mux = \"m\"\nchannel = 1\n" : "") +
        "address = 0x69\nodr_hz = 50\n" + (withDrdy ? "drdy = \"gpiochip0:2\"\n" : "");
    auto r = loadBoardText(text, "t.toml");
    EXPECT_TRUE(r.ok()) << (r.errors.empty() ? "" : r.errors[0].str());
    return *r.board;
}

TEST(BusBudget, SumsTheSensorsAtTheirRates) {
    const auto loads = computeBusLoads(twoSensorBoard(false, true));
    ASSERT_EQ(loads.size(), 1u);
    const BusLoad& l = loads[0];
    EXPECT_DOUBLE_EQ(l.transactionsPerS, 150.0);
    EXPECT_DOUBLE_EQ(l.bytesPerS, 150.0 * (3 + 23));
    EXPECT_DOUBLE_EQ(l.utilisation, 150.0 * i2cRegisterReadBits(23) / 400e3);
    ASSERT_EQ(l.sensors.size(), 2u);
    EXPECT_DOUBLE_EQ(l.sensors[0].utilisation, 100.0 * i2cRegisterReadBits(23) / 400e3);
    EXPECT_EQ(l.muxSelectsPerS, 0.0);
}

TEST(BusBudget, PollingWithoutADataReadyLineCostsAStatusRead) {
    const auto withLine = computeBusLoads(twoSensorBoard(false, true));
    const auto polled = computeBusLoads(twoSensorBoard(false, false));
    EXPECT_DOUBLE_EQ(polled[0].transactionsPerS - withLine[0].transactionsPerS, 150.0);
}

TEST(BusBudget, SwitchingMuxChannelsCostsSelects) {
    const auto loads = computeBusLoads(twoSensorBoard(true, true));
    // Two channels visited at 100 and 50 Hz.
    EXPECT_DOUBLE_EQ(loads[0].muxSelectsPerS, 150.0);
    EXPECT_DOUBLE_EQ(loads[0].transactionsPerS, 300.0);
}

}  // namespace
}  // namespace caphub::board
