// The fuzz build compiles Debian's tiny_gltf.h itself, instrumented (its JSON and glTF parsing
// is most of what the glTF target exercises); these definitions take the place of
// libtinygltf.so's.
#define TINYGLTF_IMPLEMENTATION
#include <tiny_gltf.h>
