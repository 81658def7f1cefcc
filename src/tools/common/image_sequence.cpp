#include "image_sequence.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

#include "mild_lcd/common/errors.hpp"

namespace fs = std::filesystem;

namespace mild::tools {

bool hasImageExtension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  static const char* kImageExtensions[] = {".jpg", ".jpeg", ".png",  ".bmp", ".pgm", ".ppm", ".pnm",
                                           ".tif", ".tiff", ".webp", ".jp2", ".exr", ".hdr"};
  return std::any_of(std::begin(kImageExtensions), std::end(kImageExtensions), [&](const char* e) { return ext == e; });
}

ImageSequence openImageSequence(const std::string& dir, double fallback_fps) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw InvalidInput(dir + ": not a directory");
  ImageSequence seq;
  seq.root = dir;
  seq.image_dir = fs::is_directory(fs::path(dir) / "images", ec) ? (fs::path(dir) / "images").string() : dir;
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(seq.image_dir, ec)) {
    if (entry.is_directory()) continue;
    files.push_back(entry.path().string());
  }
  if (ec) throw InvalidInput(seq.image_dir + ": cannot list the folder (" + ec.message() + ")");
  std::sort(files.begin(), files.end());
  for (const auto& f : files) (hasImageExtension(f) ? seq.frames : seq.ignored).push_back(f);
  if (seq.frames.empty()) {
    throw InvalidInput(seq.image_dir + ": no image files (" + std::to_string(files.size()) +
                       " other file(s)) — expected " + "frames such as 000000.jpg in file-name order");
  }

  std::ifstream times(fs::path(dir) / "times.txt");
  double t = 0.0;
  while (times && times >> t) seq.stamps.push_back(t);
  seq.stamps_from_file = seq.stamps.size() == seq.frames.size();
  if (!seq.stamps_from_file) {
    seq.stamps.resize(seq.frames.size());
    for (size_t i = 0; i < seq.frames.size(); ++i) seq.stamps[i] = static_cast<double>(i) / fallback_fps;
  }
  return seq;
}

}  // namespace mild::tools
