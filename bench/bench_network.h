#pragma once

// The CPU cost of the set's network (issue 39), for `previs bench`:
//   --only ltc      decoding LTC (timecode/ltc_bench.h): CPU per second of 48 kHz audio at 24,
//                   25, 29.97 DF and 30, best of the repeats;
//   --only network  one tracked frame's packets: FreeD D1 (net/freed.h encodeFreed) and an
//                   OpenTrackIO sample (net/opentrackio.h OpenTrackIOEncoder::encode, JSON and
//                   framing), with its size; the sockets' send is not included.
// Times are the thread's CPU time (CLOCK_THREAD_CPUTIME_ID), so a shared machine's other load
// shows less than in wall time. Each section runs in a few seconds. The live service's packet
// rates and delays are measured from outside by bench/network_live.sh (BENCHMARKS.md).

namespace previs::bench {

// Return the process exit code; Markdown on stdout, progress on stderr.
int runLtcBench(bool quick);
int runNetworkEncodeBench(bool quick);

}  // namespace previs::bench
