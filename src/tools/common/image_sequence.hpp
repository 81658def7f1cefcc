#pragma once

#include <optional>
#include <string>
#include <vector>

namespace mild::tools {

// An image sequence on disk: DIR's image files in file-name order (frame i = i-th file), or those of
// DIR/images when DIR has that subfolder (the ../shared/bench layout, whose gt_loops.txt and
// times.txt sit in DIR).
struct ImageSequence {
  std::string root;                  // DIR
  std::string image_dir;             // DIR or DIR/images
  std::vector<std::string> frames;   // full paths, name order
  std::vector<std::string> ignored;  // non-image files found beside the frames
  std::vector<double> stamps;        // seconds per frame: times.txt when it matches, else index / fps
  bool stamps_from_file = false;
};

// Throws mild::InvalidInput naming the folder when it does not exist or holds no image files.
ImageSequence openImageSequence(const std::string& dir, double fallback_fps = 10.0);

bool hasImageExtension(const std::string& path);

}  // namespace mild::tools
