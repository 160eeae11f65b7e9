#pragma once

// Time-of-day timecode (SMPTE ST 12-1 style "HH:MM:SS:FF", non-drop-frame) from the system
// clock, as a take stamps every frame until a real timecode source (LTC, issue 39) replaces it.

#include <cstdint>
#include <string>

namespace previs {

// The whole frames per second a timecode counts for a camera running at `fps`: 29.97 and
// 30 count 30, 23.976 counts 24 (non-drop-frame; a drop-frame count needs a real source).
int timecodeRate(double fps);

// The local time of day of `wallClockNs` (CLOCK_REALTIME) as HH:MM:SS:FF at `rate` frames a
// second, the frame number the fraction of the second elapsed.
std::string timeOfDayTimecode(uint64_t wallClockNs, int rate);

}  // namespace previs
