#pragma once

// The top of every worker thread (capture, lighting, display, button, the service's stages):
// whatever escapes the thread's body — a bug, an allocation failure, an exception from a
// library — is caught here and logged in one line naming the thread, and the owner is told so it
// can recover or stop the service with a clear message. An escaped exception would otherwise
// call std::terminate and take the box down without a word.

#include <exception>
#include <functional>
#include <new>
#include <string>

#include "base/log.h"

namespace previs {

// Runs body(); returns normally in every case. onFailure (may be empty) gets the one-line reason.
template <typename Body>
void runGuarded(const char* threadName, Body&& body,
                const std::function<void(const std::string&)>& onFailure = {}) {
    std::string reason;
    try {
        body();
        return;
    } catch (const std::bad_alloc&) {
        reason = "out of memory";
    } catch (const std::exception& e) {
        reason = e.what();
    } catch (...) {
        reason = "unknown exception";
    }
    logError("{} thread stopped: {}", threadName, reason);
    if (onFailure) onFailure(reason);
}

}  // namespace previs
