// The stage axes both protocols share: known orientations and the inverse.

#include "net/stage_pose.h"

#include <gtest/gtest.h>

#include <random>

namespace previs {
namespace {

cv::Matx44d poseMatrix(const cv::Matx33d& r, const cv::Vec3d& t) {
    return {r(0, 0), r(0, 1), r(0, 2), t[0], r(1, 0), r(1, 1), r(1, 2), t[1],
            r(2, 0), r(2, 1), r(2, 2), t[2], 0,       0,       0,       1};
}

TEST(StagePose, GltfDefaultCameraIsZero) {
    StagePose s =
        stagePoseFromWorld(poseMatrix(cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1), {1, 2, 3}));
    EXPECT_NEAR(s.panDeg, 0, 1e-12);
    EXPECT_NEAR(s.tiltDeg, 0, 1e-12);
    EXPECT_NEAR(s.rollDeg, 0, 1e-12);
    EXPECT_EQ(s.translationM, cv::Vec3d(1, -3, 2));  // X = x, Y = −z, Z = y
}

TEST(StagePose, SignsFollowTheRightHandRule) {
    // Looking along world −X (left of the default view): pan +90.
    StagePose left = stagePoseFromWorld(poseMatrix(cv::Matx33d(0, 0, -1, 0, -1, 0, -1, 0, 0), {}));
    EXPECT_NEAR(left.panDeg, 90, 1e-9);
    // Looking up (world +Y): tilt +90.
    StagePose up = stagePoseFromWorld(poseMatrix(cv::Matx33d(1, 0, 0, 0, 0, 1, 0, -1, 0), {}));
    EXPECT_NEAR(up.tiltDeg, 90, 1e-9);
    // Camera right pointing down (world −Y), view still along −Z: roll +90 (right-hand turn
    // about the view axis carries up towards camera-right).
    StagePose rolled =
        stagePoseFromWorld(poseMatrix(cv::Matx33d(0, -1, 0, -1, 0, 0, 0, 0, -1), {}));
    EXPECT_NEAR(rolled.rollDeg, 90, 1e-9);
    EXPECT_NEAR(rolled.panDeg, 0, 1e-9);
}

TEST(StagePose, InverseRoundTrips) {
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> angle(-180, 180), tilt(-90, 90), t(-50, 50);
    for (int i = 0; i < 1000; ++i) {
        StagePose s{{t(rng), t(rng), t(rng)}, angle(rng), tilt(rng), angle(rng)};
        cv::Matx44d w = worldFromStagePose(s);
        EXPECT_LT(cv::norm(worldFromStagePose(stagePoseFromWorld(w)) - w), 1e-9);
    }
}

}  // namespace
}  // namespace previs
