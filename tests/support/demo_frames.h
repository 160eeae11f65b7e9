#pragma once

// The demo session's recorded frames (examples/demo/session), read as fast as they decode: the
// input of the tests that run the service's stages on the demo take.

#include <cstddef>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "capture/recorded_source.h"
#include "tests/support/test_data.h"

namespace previs::testing {

// The first `count` frames of one of the demo session's cameras ("scene", "fisheye"), in order
// and numbered from 0; fewer when the take is shorter or a frame does not decode.
inline std::vector<std::shared_ptr<Frame>> demoFrames(
    const std::string& camera, size_t count = std::numeric_limits<size_t>::max()) {
    std::vector<std::shared_ptr<Frame>> frames;
    Result<std::unique_ptr<RecordedReader>> reader = RecordedReader::create(
        sourcePath("examples/demo/session/cameras/" + camera), ReplayTiming::AsFastAsPossible);
    if (!reader || !(*reader)->start()) return frames;
    while (!(*reader)->finished() && frames.size() < count) {
        auto f = std::make_shared<Frame>();
        Result<bool> got = (*reader)->read(1000, *f);
        if (!got) break;
        if (*got) {
            f->sequence = frames.size();
            frames.push_back(f);
        }
    }
    return frames;
}

}  // namespace previs::testing
