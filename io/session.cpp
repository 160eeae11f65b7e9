#include "io/session.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <toml++/toml.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string_view>

#include "base/atomic_file.h"
#include "base/bounded_file.h"
#include "base/log.h"

#ifndef PREVIS_VERSION
#define PREVIS_VERSION "unknown"
#endif

namespace previs {

namespace fs = std::filesystem;

namespace {

template <typename T>
bool parseNumber(std::string_view s, T& out) {
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size();
}

std::vector<std::string_view> splitFields(std::string_view line) {
    std::vector<std::string_view> fields;
    size_t start = 0;
    while (true) {
        const size_t comma = line.find(',', start);
        fields.push_back(line.substr(start, comma - start));
        if (comma == std::string_view::npos) break;
        start = comma + 1;
    }
    return fields;
}

// The complete lines of a session CSV with their 1-based numbers, as capture/recorded_source.cpp
// reads a camera index: a last line without '\n' was cut off mid-append and never counted.
// `header` is the header's prefix up to the version ("# previs-session poses v"); a header with
// a newer version is refused. `onLine` returns an error for a malformed line.
// `skipped`: when given, a malformed line is reported there and skipped instead of failing.
Status forEachLine(const std::string& path, std::string_view header, int& version,
                   const std::function<Status(int lineNo, std::string_view line)>& onLine,
                   std::vector<std::string>* skipped = nullptr) {
    // A take is untrusted: no link followed, no FIFO waited on, the size bounded before reading.
    Result<std::string> read =
        readBoundedText(path, kMaxSessionIndexBytes, FileLinks::Refuse, "session index");
    if (!read) return read.error();
    const std::string& text = *read;
    size_t pos = 0;
    int lineNo = 0;
    while (pos < text.size()) {
        const size_t eol = text.find('\n', pos);
        if (eol == std::string::npos) break;
        std::string_view line(text.data() + pos, eol - pos);
        pos = eol + 1;
        ++lineNo;
        if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
        if (line.starts_with(header)) {
            std::string_view rest = line.substr(header.size());
            rest = rest.substr(0, rest.find(':'));
            int v = 0;
            if (!parseNumber(rest, v) || v < 1)
                return makeError("{}:{}: unreadable format version in the header", path, lineNo);
            if (v > kSessionFormatVersion)
                return makeError(
                    "{}: format version {} is newer than this previs reads ({}); read it with a "
                    "newer previs",
                    path, v, kSessionFormatVersion);
            version = v;
            continue;
        }
        if (line.empty() || line[0] == '#') continue;
        if (Status s = onLine(lineNo, line); !s) {
            if (!skipped) return s;
            skipped->push_back(s.message());
        }
    }
    return {};
}

// Whether a take holds `path` at all (a link counts: it is refused when read, not skipped).
bool present(const std::string& path) {
    std::error_code ec;
    return fs::exists(fs::symlink_status(path, ec));
}

std::string nowRfc3339() {
    const std::time_t t = std::time(nullptr);
    std::tm tm{};
    gmtime_r(&t, &tm);
    char buf[32];
    std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return buf;
}

std::string errnoText() { return std::strerror(errno); }

Status writeTextAtomic(const std::string& path, const std::string& text) {
    return writeFileAtomic(path,
                           std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size()));
}

// A rename or a new file is durable once its folder is.
Status syncDir(const std::string& dir) {
    UniqueFD fd(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC));
    if (!fd.isValid()) return makeError("{}: cannot open folder: {}", dir, errnoText());
    if (::fsync(fd.get()) != 0) return makeError("{}: fsync failed: {}", dir, errnoText());
    return {};
}

bool validCameraName(const std::string& name) {
    if (name.empty() || name == "." || name == "..") return false;
    return std::all_of(name.begin(), name.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.';
    });
}

// A TOML basic string (paths may hold quotes or backslashes).
std::string tomlString(const std::string& v) {
    std::string out = "\"";
    for (char c : v) {
        if (c == '"' || c == '\\') out += '\\';
        out += c;
    }
    return out + '"';
}

// Shortest text that reads back as the same double.
std::string formatDouble(double v) { return fmt::format("{}", v); }

constexpr std::string_view kPosesHeader = "# previs-session poses v";
constexpr std::string_view kCameraIndexHeader = "# previs-session camera index v";
constexpr std::string_view kLightingHeader = "# previs-session lighting v";
// The camera index's own version (v2: wallClockNs and timecode appended; v3: exposureStops, then
// timecodeRate appended: a column old readers ignore keeps the version).
constexpr int kCameraIndexVersion = 3;
constexpr std::string_view kEventsHeader = "# previs-session events v";

bool knownEvent(std::string_view source, std::string_view event, int version) {
    if (source == "mode-button")
        // v1 did not fix the button's event names.
        return version < 2 || event == "short-press" || event == "long-press";
    if (source == "ctl")
        return event == "mode=preview" || event == "mode=refine" || event == "mode=toggle";
    if (source == "take") return event == "mode=preview" || event == "mode=refine";
    return false;
}

}  // namespace

const SessionCamera* SessionInfo::cameraWithRole(const std::string& role) const {
    for (const SessionCamera& c : cameras)
        if (c.role == role) return &c;
    return nullptr;
}

Result<std::string> containedPath(const std::string& root, const std::string& relative,
                                  const std::string& what, bool folder) {
    const fs::path rel(relative);
    auto refuse = [&](std::string_view why) -> Result<std::string> {
        return makeError("{}: '{}' {}; a session names only files inside its own folder", what,
                         relative, why);
    };
    if (relative.empty()) return refuse("is empty");
    if (rel.is_absolute()) return refuse("is an absolute path");
    fs::path at(root);
    bool below = false;  // the root itself is the caller's: it may be reached through a link
    for (const fs::path& part : rel) {
        if (part == "..") return refuse("leaves the folder ('..')");
        if (part == "." || part.empty()) continue;
        at /= part;
        below = true;
        std::error_code ec;
        const fs::file_status st = fs::symlink_status(at, ec);
        if (ec || !fs::exists(st)) return refuse("does not exist");
        if (fs::is_symlink(st)) return refuse("goes through a symbolic link");
    }
    if (folder) {
        std::error_code ec;
        if (!fs::is_directory(below ? fs::symlink_status(at, ec) : fs::status(at, ec)))
            return refuse("is not a folder");
        return at.string();
    }
    // Checked as it will be read: a FIFO or a device is refused, never waited on.
    if (Status s = checkBoundedFile(at.string(), kMaxSessionFileBytes, FileLinks::Refuse, what); !s)
        return makeError("{}; a session names only regular files of its own", s.message());
    return at.string();
}

Status syncFolder(const std::string& dir) { return syncDir(dir); }

Result<std::vector<uint8_t>> readSessionFile(const std::string& path) {
    return readBoundedFile(path, kMaxSessionFileBytes, FileLinks::Refuse, "session file");
}

Result<std::vector<RecordedFrameEntry>> loadCameraIndex(const std::string& cameraDir,
                                                        std::vector<std::string>* skipped) {
    const std::string path = cameraDir + "/index.csv";
    if (!present(path))
        return makeError(
            "{}: cannot open (is {} a session camera folder? see "
            "docs/session-format.md)",
            path, cameraDir);
    int version = 1;
    std::vector<RecordedFrameEntry> entries;
    Status s = forEachLine(
        path, kCameraIndexHeader, version,
        [&](int lineNo, std::string_view line) {
            const std::vector<std::string_view> f = splitFields(line);
            RecordedFrameEntry e;
            // Later versions may append columns (docs/session-format.md, versioning). A file is
            // a plain name in the camera's folder: never a path out of it.
            const bool plainName = f.size() >= 3 && !f[2].empty() && f[2] != "." && f[2] != ".." &&
                                   f[2].find('/') == std::string_view::npos;
            if (f.size() < 5 || !parseNumber(f[0], e.sequence) ||
                !parseNumber(f[1], e.timestampNs) || !plainName || !parseNumber(f[3], e.width) ||
                !parseNumber(f[4], e.height) || e.width == 0 || e.height == 0 || e.width > 16384 ||
                e.height > 16384)
                return Status(
                    makeError("{}:{}: malformed frame line (expected "
                              "sequence,timestampNs,file,width,height; file a plain name, sizes "
                              "1 to 16384)",
                              path, lineNo));
            if (f.size() >= 7) {
                uint64_t wall = 0;
                if (!f[5].empty()) {
                    if (!parseNumber(f[5], wall))
                        return Status(makeError("{}:{}: malformed wallClockNs", path, lineNo));
                    e.wallClockNs = wall;
                }
                e.timecode = std::string(f[6]);
            }
            if (f.size() >= 8 && !f[7].empty()) {
                float stops = 0.0f;
                if (!parseNumber(f[7], stops) || !std::isfinite(stops) || std::abs(stops) > 30.0f)
                    return Status(
                        makeError("{}:{}: malformed exposureStops (a number of stops within ±30)",
                                  path, lineNo));
                e.exposureStops = stops;
            }
            if (f.size() >= 9) {
                if (f[8].size() > 16)
                    return Status(makeError("{}:{}: malformed timecodeRate", path, lineNo));
                e.timecodeRate = std::string(f[8]);
            }
            if (!entries.empty() && (e.sequence <= entries.back().sequence ||
                                     e.timestampNs < entries.back().timestampNs))
                return Status(
                    makeError("{}:{}: sequence or timestamp goes backwards", path, lineNo));
            e.file = cameraDir + "/" + std::string(f[2]);
            entries.push_back(std::move(e));
            return Status{};
        },
        skipped);
    if (!s) return s.error();
    return entries;
}

Result<std::vector<LightingRecord>> loadLighting(const std::string& dir) {
    const std::string lightingDir = dir + "/lighting";
    const std::string path = lightingDir + "/index.csv";
    std::error_code ec;
    if (fs::is_symlink(fs::symlink_status(lightingDir, ec)))
        return makeError("{}: is a symbolic link; a take holds its lighting itself", lightingDir);
    if (!present(path)) return std::vector<LightingRecord>{};
    int version = 1;
    std::vector<LightingRecord> records;
    Status s = forEachLine(path, kLightingHeader, version, [&](int lineNo, std::string_view line) {
        // timestampNs,file,lights: the lights JSON is the rest of the line (it holds commas).
        const size_t a = line.find(',');
        const size_t b = a == std::string_view::npos ? a : line.find(',', a + 1);
        LightingRecord r;
        const std::string_view file =
            b == std::string_view::npos ? std::string_view() : line.substr(a + 1, b - a - 1);
        if (b == std::string_view::npos || !parseNumber(line.substr(0, a), r.timestampNs) ||
            file.empty() || file.find('/') != std::string_view::npos || file == "..")
            return Status(makeError(
                "{}:{}: malformed lighting line (expected timestampNs,file,lights)", path, lineNo));
        // Through the take's own lighting/ (not a link to elsewhere), to a regular file.
        Result<std::string> map =
            containedPath(dir, "lighting/" + std::string(file), fmt::format("{}:{}", path, lineNo));
        if (!map) return Status(map.error());
        r.mapFile = *map;
        r.lightsJson = std::string(line.substr(b + 1));
        records.push_back(std::move(r));
        return Status{};
    });
    if (!s) return s.error();
    return records;
}

Result<SessionInfo> openSession(const std::string& dir) {
    const std::string path = dir + "/session.toml";
    std::error_code ec;
    if (!present(path))
        return makeError("{}: not a session folder (no session.toml; see docs/session-format.md)",
                         dir);
    Result<std::string> description =
        readBoundedText(path, kMaxSessionTomlBytes, FileLinks::Refuse, "session description");
    if (!description) return description.error();
    toml::table table;
    try {
        table = toml::parse(*description, path);
    } catch (const toml::parse_error& e) {
        return makeError("{}: line {}: not valid TOML: {}", path, e.source().begin.line,
                         e.description());
    } catch (const std::exception& e) {
        return makeError("{}: {}", path, e.what());
    }
    SessionInfo info;
    info.dir = dir;
    if (table["format"].value_or(std::string()) != "previs-session")
        return makeError("{}: format is not \"previs-session\" (not a previs session)", path);
    const std::optional<int64_t> version = table["version"].value<int64_t>();
    if (!version || *version < 1)
        return makeError("{}: 'version' must be a positive integer", path);
    if (*version > kSessionFormatVersion)
        return makeError(
            "{}: session format version {} is newer than this previs reads ({}); replay it "
            "with a newer previs",
            path, *version, kSessionFormatVersion);
    info.version = int(*version);
    // A string, or a TOML date-time from a hand-written file.
    if (const toml::node* created = table.get("created")) {
        if (auto text = created->value<std::string>()) {
            info.created = *text;
        } else {
            std::ostringstream os;
            created->visit([&](const auto& n) { os << n; });
            info.created = os.str();
        }
    }
    info.clock = table["clock"].value_or(std::string("CLOCK_MONOTONIC"));
    info.previsVersion = table["previs"].value_or(std::string());
    if (present(dir + "/config.toml")) {
        info.configPath = dir + "/config.toml";
        // Relative paths in config.toml start at config_dir (v2), else at the session folder. A
        // take is untrusted whatever version it declares: config_dir names a folder inside it.
        const std::string configDir = table["config_dir"].value_or(std::string());
        info.configDirInTake = configDir;
        if (configDir.empty()) {
            info.configDir = dir;
        } else {
            Result<std::string> inside = containedPath(dir, configDir, path + ": config_dir", true);
            if (!inside) return inside.error();
            info.configDir = *inside;
        }
    }

    std::map<std::string, std::string> roles;
    if (const toml::table* cams = table["cameras"].as_table()) {
        for (const auto& [key, node] : *cams) {
            const toml::table* cam = node.as_table();
            const std::string name(key.str());
            std::optional<std::string> role =
                cam ? (*cam)["role"].value<std::string>() : std::nullopt;
            if (!role || (*role != "scene" && *role != "fisheye"))
                return makeError("{}: [cameras.{}] needs role = \"scene\" or \"fisheye\"", path,
                                 name);
            roles[name] = *role;
        }
    }
    const fs::path camerasDir = fs::path(dir) / "cameras";
    if (fs::is_symlink(fs::symlink_status(camerasDir, ec)))
        return makeError("{}: is a symbolic link; a take holds its camera folders itself",
                         camerasDir.string());
    if (fs::is_directory(camerasDir, ec)) {
        for (const fs::directory_entry& entry : fs::directory_iterator(camerasDir, ec)) {
            if (entry.is_symlink(ec))
                return makeError("{}: is a symbolic link; a take holds its camera folders itself",
                                 entry.path().string());
            if (!entry.is_directory(ec) || !present((entry.path() / "index.csv").string()))
                continue;
            SessionCamera cam;
            cam.name = entry.path().filename().string();
            cam.dir = entry.path().string();
            // Counted as a final render reads it: a corrupt line costs itself (readers that
            // replay in order refuse it when they get there).
            std::vector<std::string> skipped;
            auto index = loadCameraIndex(cam.dir, &skipped);
            if (!index) return index.error();
            cam.frames = index->size();
            if (auto it = roles.find(cam.name); it != roles.end()) cam.role = it->second;
            info.cameras.push_back(std::move(cam));
        }
    }
    std::sort(info.cameras.begin(), info.cameras.end(),
              [](const SessionCamera& a, const SessionCamera& b) { return a.name < b.name; });
    // Not a structured binding: clang 14 (the fuzz build) cannot capture one in a lambda.
    for (const auto& entry : roles) {
        const std::string& name = entry.first;
        if (std::none_of(info.cameras.begin(), info.cameras.end(),
                         [&](const SessionCamera& c) { return c.name == name; }))
            logWarning("{}: camera '{}' ({}) has no frames (no cameras/{}/index.csv)", path, name,
                       entry.second, name);
    }
    return info;
}

const char* poseKindName(PoseKind kind) {
    switch (kind) {
        case PoseKind::Tracked:
            return "tracked";
        case PoseKind::Lost:
            return "lost";
        case PoseKind::Truth:
            return "truth";
        case PoseKind::Filtered:
            return "filtered";
    }
    return "?";
}

Result<std::vector<PoseRecord>> loadPoses(const std::string& dir) {
    const std::string path = dir + "/poses.csv";
    if (!present(path)) return std::vector<PoseRecord>{};
    // v1 files had no header; their columns lack `frame`.
    int version = 1;
    std::vector<PoseRecord> poses;
    Status s = forEachLine(path, kPosesHeader, version, [&](int lineNo, std::string_view line) {
        const std::vector<std::string_view> f = splitFields(line);
        const size_t base = version >= 2 ? 2 : 1;  // index of `kind`
        auto malformed = [&](std::string_view why) -> Status {
            return makeError("{}:{}: malformed pose line ({})", path, lineNo, why);
        };
        if (f.size() < base + 19) return malformed("too few columns");
        PoseRecord p;
        if (!parseNumber(f[0], p.timestampNs)) return malformed("timestampNs");
        if (version >= 2) {
            uint64_t frame = 0;
            if (!parseNumber(f[1], frame)) return malformed("frame");
            p.frame = frame;
        }
        const std::string_view kind = f[base];
        if (kind == "tracked")
            p.kind = PoseKind::Tracked;
        else if (kind == "lost")
            p.kind = PoseKind::Lost;
        else if (kind == "truth")
            p.kind = PoseKind::Truth;
        else if (kind == "filtered")
            p.kind = PoseKind::Filtered;
        else
            return malformed("kind must be tracked, filtered, lost or truth");
        const bool empty = std::all_of(f.begin() + base + 1, f.begin() + base + 17,
                                       [](std::string_view v) { return v.empty(); });
        if (p.kind == PoseKind::Lost) {
            if (!empty) return malformed("a lost pose has no matrix");
        } else {
            std::array<double, 16> m{};
            for (int i = 0; i < 16; ++i)
                if (!parseNumber(f[base + 1 + i], m[i]) || !std::isfinite(m[i]))
                    return malformed("matrix");
            p.worldFromCamera = m;
        }
        if (!f[base + 17].empty()) {
            double e = 0.0;
            if (!parseNumber(f[base + 17], e) || !(e >= 0.0)) return malformed("reprojErrorPx");
            p.reprojErrorPx = e;
        }
        if (!parseNumber(f[base + 18], p.tags) || p.tags < 0) return malformed("tags");
        poses.push_back(std::move(p));
        return Status{};
    });
    if (!s) return s.error();
    return poses;
}

Result<std::vector<SessionEvent>> loadEvents(const std::string& dir, size_t* skippedUnknown) {
    if (skippedUnknown) *skippedUnknown = 0;
    const std::string path = dir + "/events.csv";
    if (!present(path)) return std::vector<SessionEvent>{};
    int version = 1;
    size_t skipped = 0;
    std::vector<SessionEvent> events;
    Status s = forEachLine(path, kEventsHeader, version, [&](int lineNo, std::string_view line) {
        const std::vector<std::string_view> f = splitFields(line);
        SessionEvent e;
        if (f.size() < 3 || !parseNumber(f[0], e.timestampNs) || f[1].empty() || f[2].empty())
            return Status(makeError(
                "{}:{}: malformed event line (expected timestampNs,source,event)", path, lineNo));
        // Later issues add sources; an old reader replays what it knows.
        if (!knownEvent(f[1], f[2], version)) {
            ++skipped;
            return Status{};
        }
        e.source = f[1];
        e.event = f[2];
        events.push_back(std::move(e));
        return Status{};
    });
    if (!s) return s.error();
    if (skipped > 0) logInfo("{}: {} event(s) of unknown sources skipped", path, skipped);
    if (skippedUnknown) *skippedUnknown = skipped;
    return events;
}

// --- writer -----------------------------------------------------------------------------------

Result<SessionWriter> SessionWriter::create(const std::string& dir,
                                            const SessionWriterOptions& options) {
    std::error_code ec;
    if (fs::exists(fs::path(dir) / "session.toml", ec))
        return makeError("{}: already holds a session; record into a new folder", dir);
    if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST)
        return makeError("{}: cannot create the session folder: {}", dir, errnoText());
    // A reader refuses a config_dir outside the session: never write one.
    if (const fs::path configDir(options.configDir);
        configDir.is_absolute() || std::any_of(configDir.begin(), configDir.end(),
                                               [](const fs::path& p) { return p == ".."; }))
        return makeError("{}: config_dir '{}' leaves the session; name a folder inside it", dir,
                         options.configDir);
    for (const auto& [name, role] : options.cameraRoles) {
        if (!validCameraName(name))
            return makeError("session camera name '{}': use letters, digits, '-', '_', '.'", name);
        if (role != "scene" && role != "fisheye")
            return makeError("session camera '{}': role '{}' is not scene or fisheye", name, role);
    }

    // A session whose config names files in a folder outside it (config_dir: a generated
    // session shipped beside its config, as the bundled demo) is a v2 session; v3 is a take,
    // which holds everything it names and is read as untrusted (docs/session-format.md).
    const int version = options.configDir.empty() ? kSessionFormatVersion : 2;
    std::string toml = fmt::format(
        "format = \"previs-session\"\nversion = {}\ncreated = \"{}\"\nclock = \"CLOCK_MONOTONIC\"\n"
        "previs = \"{}\"\n",
        version, options.created.empty() ? nowRfc3339() : options.created,
        options.previsVersion.empty() ? PREVIS_VERSION : options.previsVersion);
    if (!options.configDir.empty())
        toml += fmt::format("config_dir = {}\n", tomlString(options.configDir));
    for (const auto& [name, role] : options.cameraRoles)
        toml += fmt::format("\n[cameras.{}]\nrole = \"{}\"\n", name, role);

    SessionWriter w;
    w.dir_ = dir;
    w.lastSync_ = std::chrono::steady_clock::now();
    w.flushInterval_ = options.flushInterval;
    // config.toml first: a folder with session.toml is a session, and should be complete.
    if (!options.configToml.empty())
        if (Status s = writeTextAtomic(dir + "/config.toml", options.configToml); !s)
            return s.error();
    if (Status s = writeTextAtomic(dir + "/session.toml", toml); !s) return s.error();
    if (Status s = syncDir(dir); !s) return s.error();
    // The new folder's own entry lives in its parent.
    if (Status s = syncDir(fs::absolute(dir).parent_path().string()); !s) return s.error();
    return w;
}

SessionWriter::~SessionWriter() {
    if (dir_.empty()) return;  // moved from
    if (Status s = flush(); !s) logError("{}", s.message());
}

Result<SessionWriter::Index*> SessionWriter::openIndex(const std::string& relPath,
                                                       const std::string& header) {
    if (auto it = indices_.find(relPath); it != indices_.end()) return &it->second;
    Index index;
    index.path = dir_ + "/" + relPath;
    index.fd =
        UniqueFD(::open(index.path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644));
    if (!index.fd.isValid())
        return makeError("{}: cannot open for appending: {}", index.path, errnoText());
    struct stat st {};
    if (::fstat(index.fd.get(), &st) != 0)
        return makeError("{}: cannot stat: {}", index.path, errnoText());
    if (st.st_size == 0) {
        if (Status s = appendLine(index, header); !s) return s.error();
        newEntries_ = true;
    }
    return &indices_.emplace(relPath, std::move(index)).first->second;
}

Status SessionWriter::appendLine(Index& index, const std::string& line) {
    PV_DCHECK(!line.empty() && line.back() == '\n');
    // One write() per line: after a crash a line is whole or cut short (and then ignored),
    // never interleaved. A short write gets one more for the rest: a full disk then says so
    // (ENOSPC), and a write a signal cut short is completed.
    const off_t before = ::lseek(index.fd.get(), 0, SEEK_END);
    size_t written = 0;
    std::string why;
    for (int attempt = 0; attempt < 2 && written < line.size() && why.empty(); ++attempt) {
        ssize_t n;
        do {
            n = ::write(index.fd.get(), line.data() + written, line.size() - written);
        } while (n < 0 && errno == EINTR);
        if (n < 0)
            why = errnoText();
        else
            written += size_t(n);
    }
    if (written == line.size()) {
        index.dirty = true;
        return {};
    }
    if (why.empty()) why = fmt::format("short write ({} of {} bytes)", written, line.size());
    // The fragment is cut back off: readers skip only a cut *last* line, so a fragment that a
    // later line were appended to would make the index unreadable.
    if (written > 0 && before >= 0 && ::ftruncate(index.fd.get(), before) != 0) {
        index.fd.reset();  // the fragment stays: no later line may follow it
        return makeError(
            "{}: {} and the fragment could not be removed: {}; this index takes no more lines",
            index.path, why, errnoText());
    }
    return makeError("{}: write failed: {} (is the disk full?)", index.path, why);
}

Status SessionWriter::syncIfDue() {
    // At least every flushInterval (docs/session-format.md): a power cut loses at most that.
    if (std::chrono::steady_clock::now() - lastSync_ < flushInterval_) return {};
    return flush();
}

bool SessionWriter::unsynced() const {
    return newEntries_ || std::any_of(indices_.begin(), indices_.end(),
                                      [](const auto& index) { return index.second.dirty; });
}

std::optional<std::chrono::steady_clock::time_point> SessionWriter::flushDue() const {
    if (!unsynced()) return std::nullopt;
    return lastSync_ + flushInterval_;
}

Status SessionWriter::flushIfDue() {
    if (!unsynced()) return {};
    return syncIfDue();
}

Status SessionWriter::flush() {
    Status result;
    // Folders first: a durable index line must never name a file whose rename is not.
    if (newEntries_) {
        // New folders' entries live in their parents; renamed frames and new index files in
        // the folders of the indices.
        std::set<std::string> folders = newFolders_;
        for (auto& [rel, index] : indices_) folders.insert(fs::path(index.path).parent_path());
        folders.insert(dir_);
        for (const std::string& folder : folders)
            if (Status s = syncDir(folder); !s && result) result = s;
        newFolders_.clear();
        newEntries_ = false;
    }
    for (auto& [rel, index] : indices_) {
        if (!index.dirty) continue;
        if (::fdatasync(index.fd.get()) != 0 && result)
            result = makeError("{}: fdatasync failed: {}", index.path, errnoText());
        index.dirty = false;
    }
    lastSync_ = std::chrono::steady_clock::now();
    return result;
}

Status SessionWriter::createFolder(const std::string& relPath) {
    const fs::path folder = fs::path(dir_) / relPath;
    std::error_code ec;
    if (fs::is_directory(folder, ec)) return {};
    fs::create_directories(folder, ec);
    if (ec) return makeError("{}: cannot create: {}", folder.string(), ec.message());
    for (fs::path p = folder; p != fs::path(dir_) && p.has_parent_path(); p = p.parent_path())
        newFolders_.insert(p.parent_path().string());
    newEntries_ = true;
    return {};
}

Status SessionWriter::writeFrame(const std::string& camera, uint64_t sequence, uint64_t timestampNs,
                                 std::span<const uint8_t> encoded, const std::string& ext,
                                 uint32_t width, uint32_t height, const FrameStamp& stamp) {
    if (!validCameraName(camera))
        return makeError("session camera name '{}': use letters, digits, '-', '_', '.'", camera);
    // png, jpg, or a raw format's fourcc in lower case (yuyv, nv12, ...).
    if (ext.size() < 2 || ext.size() > 4 || !std::all_of(ext.begin(), ext.end(), [](char c) {
            return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9');
        }))
        return makeError("session frame of '{}': extension '{}' is not png, jpg or a fourcc",
                         camera, ext);
    if (width == 0 || height == 0 || encoded.empty())
        return makeError("session frame {} of '{}': empty frame", sequence, camera);
    const std::string camDir = dir_ + "/cameras/" + camera;
    const std::string rel = "cameras/" + camera + "/index.csv";
    if (indices_.find(rel) == indices_.end())
        if (Status s = createFolder("cameras/" + camera); !s) return s;
    auto index = openIndex(rel, fmt::format("{}{}: sequence,timestampNs,file,width,height,"
                                            "wallClockNs,timecode,exposureStops,timecodeRate\n",
                                            kCameraIndexHeader, kCameraIndexVersion));
    if (!index) return index.error();
    Index& idx = **index;
    if ((idx.lastSequence && sequence <= *idx.lastSequence) || timestampNs < idx.lastTimestampNs)
        return makeError(
            "{}: frame {} at {} ns after frame {} at {} ns: sequences must increase and "
            "timestamps not decrease",
            idx.path, sequence, timestampNs, idx.lastSequence.value_or(0), idx.lastTimestampNs);
    const std::string file = fmt::format("{:012d}.{}", sequence, ext);
    if (Status s = writeFileAtomic(camDir + "/" + file, encoded); !s) return s;
    newEntries_ = true;
    for (const std::string* field : {&stamp.timecode, &stamp.timecodeRate})
        if (field->find_first_of(",\n\r") != std::string::npos)
            return makeError("session frame {} of '{}': timecode '{}' holds a comma or newline",
                             sequence, camera, *field);
    if (Status s = appendLine(
            idx, fmt::format(
                     "{},{},{},{},{},{},{},{},{}\n", sequence, timestampNs, file, width, height,
                     stamp.wallClockNs ? std::to_string(*stamp.wallClockNs) : std::string(),
                     stamp.timecode,
                     stamp.exposureStops ? fmt::format("{}", *stamp.exposureStops) : std::string(),
                     stamp.timecodeRate));
        !s)
        return s;
    idx.lastSequence = sequence;
    idx.lastTimestampNs = timestampNs;
    return syncIfDue();
}

Status SessionWriter::writePose(const PoseRecord& pose) {
    if (!pose.frame)
        return makeError("session pose at {} ns: v2 poses need a frame", pose.timestampNs);
    if ((pose.kind == PoseKind::Lost) == pose.worldFromCamera.has_value())
        return makeError("session pose of frame {}: a {} pose {} a matrix", *pose.frame,
                         poseKindName(pose.kind), pose.kind == PoseKind::Lost ? "has no" : "needs");
    auto index =
        openIndex("poses.csv", fmt::format("{}{}: timestampNs,frame,kind,m00,...,m33,reprojErrorPx,"
                                           "tags\n",
                                           kPosesHeader, kSessionFormatVersion));
    if (!index) return index.error();
    std::string line =
        fmt::format("{},{},{}", pose.timestampNs, *pose.frame, poseKindName(pose.kind));
    for (int i = 0; i < 16; ++i) {
        line += ',';
        if (pose.worldFromCamera) {
            if (!std::isfinite((*pose.worldFromCamera)[i]))
                return makeError("session pose of frame {}: matrix is not finite", *pose.frame);
            line += formatDouble((*pose.worldFromCamera)[i]);
        }
    }
    line += ',';
    if (pose.reprojErrorPx && std::isfinite(*pose.reprojErrorPx))
        line += formatDouble(*pose.reprojErrorPx);
    line += fmt::format(",{}\n", pose.tags);
    if (Status s = appendLine(**index, line); !s) return s;
    return syncIfDue();
}

Status SessionWriter::appendRecord(const std::string& relPath, const std::string& header,
                                   const std::string& line) {
    auto index = openIndex(relPath, header + "\n");
    if (!index) return index.error();
    if (Status s = appendLine(**index, line); !s) return s;
    return syncIfDue();
}

Status SessionWriter::writeEvent(const SessionEvent& event) {
    auto bad = [](const std::string& v) {
        return v.empty() || v.find_first_of(",\n\r") != std::string::npos;
    };
    if (bad(event.source) || bad(event.event))
        return makeError(
            "session event '{}','{}': source and event must be non-empty and hold "
            "no comma or newline",
            event.source, event.event);
    auto index = openIndex("events.csv", fmt::format("{}{}: timestampNs,source,event\n",
                                                     kEventsHeader, kSessionFormatVersion));
    if (!index) return index.error();
    if (Status s = appendLine(
            **index, fmt::format("{},{},{}\n", event.timestampNs, event.source, event.event));
        !s)
        return s;
    return syncIfDue();
}

Status SessionWriter::writeLighting(uint64_t timestampNs,
                                    const std::function<Status(AtomicFile& file)>& writeMap,
                                    const std::string& lightsJson) {
    if (lightsJson.find_first_of("\n\r") != std::string::npos)
        return makeError("session lighting at {} ns: the lights JSON must be one line",
                         timestampNs);
    if (indices_.find("lighting/index.csv") == indices_.end())
        if (Status s = createFolder("lighting"); !s) return s;
    auto index = openIndex(
        "lighting/index.csv",
        fmt::format("{}{}: timestampNs,file,lights\n", kLightingHeader, kSessionFormatVersion));
    if (!index) return index.error();
    const std::string file = fmt::format("{:06d}.exr", lightingSnapshots_);
    Result<AtomicFile> map = AtomicFile::create(dir_ + "/lighting/" + file);
    if (!map) return map.error();
    if (Status s = writeMap(*map); !s) return s;
    if (Status s = map->commit(); !s) return s;
    newEntries_ = true;
    ++lightingSnapshots_;
    if (Status s = appendLine(**index, fmt::format("{},{},{}\n", timestampNs, file, lightsJson));
        !s)
        return s;
    return syncIfDue();
}

}  // namespace previs
