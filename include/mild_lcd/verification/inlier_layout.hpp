#pragma once

// How the inliers of a two-view fit sit in the images: evidence the candidate scorer weighs beside
// their number. A true revisit shares most of the view, so its inliers spread over the image and
// over scene planes at several depths; a repeated texture (one facade material on many walls)
// matches in one patch, on one plane.

#include <vector>

#include <opencv2/core.hpp>

namespace mild {

// Fraction of the image's occupied cells that hold an inlier: the keypoints' bounding box is cut
// into 8 x 6 cells, a cell is occupied when any keypoint falls in it. 0 without inliers.
double inlierCoverage(const std::vector<cv::KeyPoint>& keypoints, const std::vector<cv::Point2f>& inliers);

// Fraction of the inliers that one homography explains (RANSAC, 3 px): near 1 when they lie on one
// plane. 0 for fewer than 8 inliers.
double homographyShare(const std::vector<cv::Point2f>& query_inliers, const std::vector<cv::Point2f>& train_inliers);

}  // namespace mild
