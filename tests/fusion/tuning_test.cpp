// The leave-one-out selection: each held-out trial gets the candidate that is best on the others,
// so a candidate that wins only through one trial does not score that trial.
#include "fusion/tuning.h"

#include <gtest/gtest.h>

namespace caphub::fusion {
namespace {

TEST(Tuning, LeaveOneOutNeverChoosesWithTheHeldOutTrial) {
    // Candidate 1 is best in-sample only because of trial 2; held out, trial 2 gets candidate 0,
    // the best on trials 0 and 1.
    const std::vector<std::vector<double>> scores{
        {1.0, 1.0, 5.0},
        {1.5, 1.5, 1.0},
        {2.0, 2.0, 2.0},
    };
    EXPECT_EQ(inSampleChoice(scores), 1U);  // sums 7, 4, 6
    const auto loo = leaveOneOutChoice(scores);
    ASSERT_EQ(loo.size(), 3U);
    EXPECT_EQ(loo[0], 1U);  // trials 1, 2: 6, 2.5, 4
    EXPECT_EQ(loo[1], 1U);
    EXPECT_EQ(loo[2], 0U);  // trials 0, 1: 2, 3, 4
}

TEST(Tuning, TooFewTrialsGiveNoChoice) {
    EXPECT_TRUE(leaveOneOutChoice({}).empty());
    EXPECT_TRUE(leaveOneOutChoice({{1.0}, {2.0}}).empty());
}

TEST(Tuning, TheSearchSpaceStartsAtTheDefaultsAndIsValid) {
    const auto space = tuningSearchSpace();
    ASSERT_EQ(space.size(), 27U);
    const FilterParams d;
    EXPECT_EQ(space[0].params.tauAccS, d.tauAccS);
    EXPECT_EQ(space[0].params.accLpDamping, d.accLpDamping);
    EXPECT_EQ(space[0].params.headingNoiseDegRtHz, d.headingNoiseDegRtHz);
    for (const auto& c : space) {
        EXPECT_EQ(invalidFilterParameter(c.params), nullptr) << c.label;
    }
}

}  // namespace
}  // namespace caphub::fusion
