#pragma once

// Where previs finds data at run time. Nothing here is a path compiled in: a binary copied to
// another machine, installed under another prefix or built in another checkout finds its data
// the same way.
//   shared data (test and benchmark inputs, ../shared/data beside the checkout):
//     $PREVIS_DATA_DIR (when set, even to a missing folder: then there are none), else a
//     `shared/data` folder in an ancestor of the executable;
//   the project's own files (examples, bundled data):
//     <prefix>/share/previs when installed (the executable in <prefix>/bin), else the checkout
//     the executable was built in (an ancestor holding examples/demo/previsd.toml).

#include <filesystem>
#include <optional>
#include <string_view>

namespace previs {

// The folder of the running executable (/proc/self/exe).
std::filesystem::path executableDir();

// The first ancestor A of `start` (itself included) with A/relative existing, as A/relative.
std::optional<std::filesystem::path> findUpward(const std::filesystem::path& start,
                                                const std::filesystem::path& relative);

// The shared data folder, or nullopt (then data-driven tests skip and say why).
std::optional<std::filesystem::path> sharedDataDir();

// The project's data root: <prefix>/share/previs installed, else the checkout's root.
std::optional<std::filesystem::path> projectDataDir();

}  // namespace previs
