#include "base/data_paths.h"

#include <cstdlib>
#include <system_error>

namespace previs {

namespace fs = std::filesystem;

fs::path executableDir() {
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    return ec ? fs::current_path(ec) : exe.parent_path();
}

std::optional<fs::path> findUpward(const fs::path& start, const fs::path& relative) {
    std::error_code ec;
    for (fs::path dir = start; !dir.empty(); dir = dir.parent_path()) {
        if (fs::exists(dir / relative, ec)) return dir / relative;
        if (dir == dir.root_path()) break;
    }
    return std::nullopt;
}

std::optional<fs::path> sharedDataDir() {
    std::error_code ec;
    // A folder the environment names wins, even when it does not exist (then: no data).
    for (const char* var : {"PREVIS_DATA_DIR", "PREVIS_SHARED_DATA"}) {
        const char* value = std::getenv(var);
        if (value && *value)
            return fs::is_directory(value, ec) ? std::optional<fs::path>(value) : std::nullopt;
    }
    return findUpward(executableDir(), "shared/data");
}

std::optional<fs::path> projectDataDir() {
    std::error_code ec;
    const fs::path installed = executableDir().parent_path() / "share" / "previs";
    if (fs::is_directory(installed, ec)) return installed;
    if (auto marker = findUpward(executableDir(), "examples/demo/previsd.toml"))
        return marker->parent_path().parent_path().parent_path();
    return std::nullopt;
}

}  // namespace previs
