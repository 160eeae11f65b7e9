// The fuzz build compiles Debian's stb_image.h itself, instrumented, so libFuzzer sees coverage
// inside the image decoders and ASan checks their memory accesses; these definitions take the
// place of libstb.so's (for previs and for libtinygltf alike).
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
