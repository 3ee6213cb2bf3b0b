#include "hal/chip_info.h"

#include <gtest/gtest.h>

namespace caphub::hal {
namespace {

TEST(ChipInfo, FindsChipsByBoardFileName) {
    ASSERT_NE(findChip("icm20948"), nullptr);
    ASSERT_NE(findChip("lsm6dsox+lis3mdl"), nullptr);
    EXPECT_EQ(findChip("mpu9250"), nullptr);
}

TEST(ChipInfo, Icm20948RunsAt1100OverOnePlusDivider) {
    const ChipInfo& icm = *findChip("icm20948");
    for (double hz : {1100.0, 550.0, 100.0, 50.0, 1100.0 / 256}) {
        EXPECT_TRUE(odrSupported(icm, hz)) << hz;
    }
    for (double hz : {200.0, 60.0, 2000.0, 4.0, 0.0, -50.0}) {
        EXPECT_FALSE(odrSupported(icm, hz)) << hz;
    }
    const auto n = odrNeighbours(icm, 200);
    ASSERT_EQ(n.size(), 2u);
    EXPECT_NEAR(n[0], 1100.0 / 6, 1e-9);
    EXPECT_NEAR(n[1], 220.0, 1e-9);
}

TEST(ChipInfo, LsmRunsAtItsListedRates) {
    const ChipInfo& lsm = *findChip("lsm6dsox+lis3mdl");
    EXPECT_TRUE(odrSupported(lsm, 104));
    EXPECT_TRUE(odrSupported(lsm, 12.5));
    EXPECT_FALSE(odrSupported(lsm, 100));
    const auto n = odrNeighbours(lsm, 100);
    ASSERT_EQ(n.size(), 2u);
    EXPECT_EQ(n[0], 52.0);
    EXPECT_EQ(n[1], 104.0);
}

TEST(ChipInfo, OneSampleIsOneBurstForAccelGyroAndMagnetometer) {
    const ChipInfo& icm = *findChip("icm20948");
    EXPECT_EQ(icm.imuRead.transactions, 1);
    EXPECT_EQ(icm.imuRead.dataBytes, 23);
    EXPECT_EQ(icm.magRead.transactions, 0);
    EXPECT_LE(icm.imuRead.dataBytes, 32);  // fits one SMBus I2C block transfer
}

}  // namespace
}  // namespace caphub::hal
