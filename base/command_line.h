#pragma once

// What previs and previsd share about their command lines (DESIGN.md §3): usage errors are one
// line naming the command and the option, exit code 2; --help and --version exit 0; anything a
// command throws is caught at the top, reported in one line, exit 1.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <new>
#include <optional>
#include <string>

namespace previs {

// Exit codes, the same rule in every command.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  // a runtime failure: a device, a write, the GPU
inline constexpr int kExitUsage = 2;    // bad usage or bad input (a file that cannot be used)

// "previs render: --width: Value 0 not in range [1 - 16384]; see previs render --help".
inline void useOneLineUsageErrors(CLI::App& app) {
    app.failure_message([](const CLI::App* top, const CLI::Error& e) {
        std::string command = top->get_name();
        for (const CLI::App* sub : top->get_subcommands()) command += " " + sub->get_name();
        return command + ": " + e.what() + "; see " + command + " --help\n";
    });
}

// Parses; on --help/--version or a usage error returns the exit code to leave with.
inline std::optional<int> parseCommandLine(CLI::App& app, int argc, char** argv) {
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        return app.exit(e) == 0 ? kExitOk : kExitUsage;
    }
    return std::nullopt;
}

// Runs `body`; an exception that escaped it (a bug, or memory exhausted) is one line and exit 1.
template <typename Body>
int runReportingExceptions(const char* program, Body&& body) {
    try {
        return body();
    } catch (const std::bad_alloc&) {
        std::fprintf(stderr,
                     "%s: error: out of memory (the input may be larger than this "
                     "machine can hold; try a smaller resolution or scene)\n",
                     program);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s: internal error: %s (please report it with the command line)\n",
                     program, e.what());
    } catch (...) {
        std::fprintf(stderr,
                     "%s: internal error: unknown exception (please report it with the "
                     "command line)\n",
                     program);
    }
    return kExitFailure;
}

}  // namespace previs
