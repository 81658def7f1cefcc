#pragma once

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace mild {

// A file named by a client, pinned down: an open handle on the folder that holds it plus its name
// in that folder. Every later step (open, create, rename) goes through the handle, so renaming or
// replacing folders on the path meanwhile cannot redirect it elsewhere.
class ConfinedFile {
 public:
  ConfinedFile(int folder_fd, std::string name, std::string display);
  ConfinedFile(ConfinedFile&& other) noexcept;
  ConfinedFile& operator=(ConfinedFile&& other) noexcept;
  ConfinedFile(const ConfinedFile&) = delete;
  ConfinedFile& operator=(const ConfinedFile&) = delete;
  ~ConfinedFile();

  int folder() const { return folder_fd_; }
  const std::string& name() const { return name_; }
  const std::string& display() const { return display_; }  // for messages: the path as resolved

  // Opens the file for reading. Refuses (InvalidInput) a symbolic link, FIFO, socket, device or
  // folder, and never blocks on one, and a file with other hard links (one planted in the folder
  // could name any file on the disk); a missing file is an IoError. Returns the descriptor and the
  // file's size.
  int openForReading(unsigned long long& size) const;
  // Throws InvalidInput when something other than a regular file sits at the name (a symbolic
  // link, a device, a folder), so that a save never replaces one.
  void refuseIfNotRegular() const;
  bool exists() const;
  // Replaces the file crash-safely with what `write` writes to the descriptor it is given: the
  // content goes to a temporary file of its own in the same folder (".<name>.mild-lcd-save.<16 hex
  // digits>", created exclusively, never through a link, locked while written), is flushed to disk
  // (fsync), then renamed over the file, so a crash at any moment leaves either the previous file or
  // the new one, both complete. Concurrent replacements never share a temporary file: each leaves a
  // complete file, the last rename wins. `signature` is how every file `write` writes begins (the
  // format's magic): replace writes it to the temporary file first, and `write` must leave those
  // bytes as they are (or write the same again). Temporary files left by killed replacements are
  // removed first, and only they: a name of that pattern, a regular file with one name, owned by
  // this process's user, beginning with `signature` (or a beginning of it), unlocked and older than
  // a minute; anything else is never touched. Throws InvalidInput when something other than a
  // regular file sits at the name, IoError when the file cannot be written; whatever `write` throws
  // is passed on. The previous file is kept on any failure.
  void replace(const std::function<void(int fd)>& write, std::string_view signature) const;
  // replace() with `text` as the whole content (which must begin with `signature`).
  void replaceText(const std::string& text, std::string_view signature) const;
  // The whole file as openForReading opens it. Throws IoError when it cannot be read whole.
  std::string readText() const;

 private:
  int folder_fd_ = -1;
  std::string name_;
  std::string display_;
};

// Whether `name` (a file name, no folder) has the pattern of a save's temporary file
// (ConfinedFile::replace): such names are refused as map names, so that only a save makes them.
bool isTemporaryFileName(const std::string& name);

// What a station of a team across hosts saves beside its maps: "<station>" + kTeamLedgerSuffix,
// replaced as a map is (ConfinedFile::replace). No client-named path may use that name or that name
// + kTeamLedgerTemporarySuffix, as a file or as a folder: a client must not make or replace a
// station's ledger.
constexpr const char* kTeamLedgerSuffix = ".team_ledger.json";
constexpr const char* kTeamLedgerTemporarySuffix = ".writing";
bool isTeamLedgerName(const std::string& name);

// A file named by an ordinary path, for tools and tests that trust their paths: the folder is
// followed as given (symbolic links included); the file itself is still opened without following
// a link.
ConfinedFile fileAtPath(const std::string& path);

// What saves may leave in the folder: names at most max_depth folders deep; a save that would
// create a file or folder is refused once the folder holds max_entries files and folders, or when
// its files (other than the one replaced) already hold max_bytes.
struct DirectoryLimits {
  size_t max_depth = 8;
  size_t max_entries = 100;
  unsigned long long max_bytes = 64ull << 30;
};

// The one folder database files may be saved to and loaded from, for names that come from ROS
// clients (the node often runs as root). A name resolves inside it or is refused:
//   - relative names ("map.db", "site_a/map.db") are taken from the folder; absolute ones must lie
//     inside it;
//   - no "..", no empty or "." components, no symbolic link at any level below the folder;
//   - at most 4096 bytes, 255 per component (223 for the name of a file saved: its temporary
//     file's name is 32 bytes longer), DirectoryLimits::max_depth folders deep;
//   - not the name of a save's temporary file (isTemporaryFileName), and no component the name of
//     a team ledger or its temporary file (isTeamLedgerName);
//   - saving within DirectoryLimits.
// The folder itself is configured by the operator and may be a symbolic link.
class DatabaseDirectory {
 public:
  // Creates the folder (and missing parents) when absent. Throws InvalidInput for a relative
  // path, IoError when it cannot be created or opened.
  explicit DatabaseDirectory(const std::string& root, const DirectoryLimits& limits = {});
  const std::string& root() const { return root_; }

  // Throws InvalidInput naming the rule the request broke. create_folders (for saving) checks the
  // DirectoryLimits, then makes missing sub-folders.
  ConfinedFile resolve(const std::string& requested, bool create_folders = false) const;
  // The absolute path `requested` resolves to, or "" when it is refused (no file is touched).
  std::string describe(const std::string& requested) const;

 private:
  // Throws InvalidInput when saving `parts` would leave more than the limits allow.
  void checkRoomFor(const std::vector<std::string>& parts, const std::string& requested) const;

  std::string root_;
  DirectoryLimits limits_;
};

}  // namespace mild
