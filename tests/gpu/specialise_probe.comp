#version 460
// SpecialiseTest's shader: a feature switch guarding a call (removed with its function when
// off), a switch folded into a condition with a run-time value, and a 32-bit constant.
layout(local_size_x = 64) in;
layout(constant_id = 0) const bool kDoubleLarge = true;
layout(constant_id = 1) const bool kSquare = true;
layout(constant_id = 2) const uint kOffset = 0u;
layout(binding = 0) buffer Values { uint values[]; };

uint squared(uint v) { return v * v; }

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint v = values[i];
    if (kDoubleLarge && v > 3u) v *= 2u;
    if (kSquare) v = squared(v);
    values[i] = v + kOffset;
}
