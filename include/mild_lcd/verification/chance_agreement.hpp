#pragma once

// How surprising a two-view model's inliers are, measured against what chance would give for that
// very pair (the a-contrario number of false alarms of Moisan and Stival's ORSA). The raw inlier
// count means different things at 200 and at 2,000 matches, for a 160 x 120 and a 640 x 480 image:
// a wrong pair's chance inliers grow with the matches fed to the model and with the share of the
// image the inlier tolerance covers. The number of false alarms divides both out, so that one
// scorer holds for every descriptor, feature budget and resolution.

#include <vector>

#include <opencv2/core/types.hpp>

namespace mild {

// The probability that a match placed uniformly at random agrees with a given two-view model: its
// point falls within `tolerance_px` of the epipolar line, which crosses the area the image's
// keypoints occupy (their bounding box) over at most its diagonal: 2 t D / A, in (0, 1]. 1 (no
// evidence possible) for fewer than two keypoints or a degenerate box.
double chanceInlierProbability(const std::vector<cv::KeyPoint>& keypoints, double tolerance_px);

// A lower bound of chanceInlierProbability for any image a keyframe plausibly has (a 1-pixel
// tolerance over 2,000 x 2,000 pixels gives 1.4e-3): what a caller that has not fitted a model yet
// uses to bound the significance a model could reach from above.
constexpr double kLeastChanceInlierProbability = 1e-3;

// The minimal samples of the two-view models verification fits: five points for an essential
// matrix (both cameras known), seven for a fundamental one.
constexpr int kEssentialSample = 5;
constexpr int kFundamentalSample = 7;

// log10 of the number of false alarms of a model fitted by minimal samples of `sample_size` matches
// with `inliers` of `matches` agreeing, each match agreeing by chance with `chance_probability`:
// NFA = (matches - sample_size) C(matches, inliers) C(inliers, sample_size) p^(inliers - sample_size).
// Below 0 (fewer than one such model expected by chance), the agreement is meaningful; -10 means
// chance gives it once in 10^10 trials. 0 when inliers <= sample_size (no evidence).
double log10FalseAlarms(int matches, int inliers, double chance_probability, int sample_size);

}  // namespace mild
