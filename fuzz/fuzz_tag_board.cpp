// loadTagBoard on a board .toml (docs/board-format.md).
#include "fuzz/fuzz_support.h"
#include "vision/board_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    const std::string path = fuzz::writeScratch("board.toml", fuzz::asText(data, size));
    Result<TagBoard> board = loadTagBoard(path);
    if (board.ok())
        for (const BoardTag& tag : board->tags()) (void)board->worldCorners(tag);
    return 0;
}
