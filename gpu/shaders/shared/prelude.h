// Lets one header be compiled as GLSL (by glslang) and as C++ (with GLM, whose types and
// functions follow GLSL's). Shared headers hold struct layouts, binding numbers and the math that
// must agree on both sides; C++ tests run the same math on the CPU.
//
// Rules for shared code: float literals carry an `f` suffix (GLM does not mix double and float),
// out/inout parameters use PV_OUT/PV_INOUT, and everything sits between PV_BEGIN and PV_END.
#ifndef PREVIS_SHARED_PRELUDE_H
#define PREVIS_SHARED_PRELUDE_H

#ifdef __cplusplus
#include <cstdint>

#include <glm/glm.hpp>
#include <glm/gtc/constants.hpp>

#define PV_BEGIN                  \
    namespace previs::shader {    \
    using namespace glm;          \
    using uint = std::uint32_t;
#define PV_END }
#define PV_OUT(T) T&
#define PV_INOUT(T) T&
#define PV_INLINE inline
#else
#define PV_BEGIN
#define PV_END
#define PV_OUT(T) out T
#define PV_INOUT(T) inout T
#define PV_INLINE
#endif

// Counts one iteration of a loop whose trip count depends on the data (BVH traversal, binary
// searches, path bounces). llvmpipe (lavapipe) ends every loop of a shader invocation once
// 65535 iterations of all its loops together have run (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS,
// shared by all loops): a dispatch that runs longer silently loses work. The GLSL side counts
// so the renderer can keep each dispatch far below that budget; shaders that include a header
// using this define PV_COUNT_LOOP_ITERATION before including it.
#ifndef PV_COUNT_LOOP_ITERATION
#define PV_COUNT_LOOP_ITERATION()
#endif

// How llvmpipe runs control flow (Mesa 22.3's gallivm), which shapes the loops of these shaders:
// an `if` does not branch, both sides run under a lane mask; a loop is always entered and tests
// its mask only at the end of its body. So a loop tests its exit at the end (`for (;;) { ...;
// if (done) break; }`): a test at the top runs the whole body once more, masked, after the last
// lane of the SIMD batch has left. And code that must run at most once per pass of an enclosing
// loop appears in it once: every copy of a loop runs at least once per pass, needed or not
// (bench/results/benchmarks_2026-11-29.md, "llvmpipe runs every branch").

#define PV_PI 3.14159265358979323846f
#define PV_INV_PI 0.31830988618379067154f
#define PV_TWO_PI 6.28318530717958647692f
#define PV_INV_TWO_PI 0.15915494309189533577f
// The largest float below 1: keeps a uniform sample in [0, 1) when it is built from bits.
#define PV_ONE_MINUS_EPSILON 0.99999994f
#define PV_FLOAT_MAX 3.402823466e+38f

#endif
