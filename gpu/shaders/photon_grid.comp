// photon_grid: sorts the iteration's photon records by grid bucket and records each bucket's
// range, so the gather finds a bucket's photons contiguous. First the stored records' sort pairs,
// which trace_photons left packed per workgroup, are gathered into one array (a scan of the
// groups' counts, then a move): the sort then costs what the stored records need, not the four
// slots every photon has. Then a stable least-significant-digit radix sort of the 24-bit bucket
// keys, PV_PHOTON_SORT_PASSES passes of 8 bits (params.photonSortShift), each three dispatches —
// per-block digit histograms, one scan over them, a stable scatter — then the cell pass. Stable
// and free of order-dependent atomics, so a bucket's records come out in photon order on every
// run: the gather's bucket subsampling, and with it every pixel, is deterministic.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "gpu/shaders/shared/scene_types.h"
#include "gpu/shaders/shared/photon_records.h"

#define STAGE_HISTOGRAM 0u
#define STAGE_SCAN 1u
#define STAGE_SCATTER 2u
#define STAGE_CELLS 3u
#define STAGE_COMPACT_SCAN 4u
#define STAGE_COMPACT 5u
layout(constant_id = 0) const uint kStage = STAGE_HISTOGRAM;

// The scan runs in one workgroup of PV_PHOTON_SCAN_GROUP, the histogram and the scatter in one
// invocation per block of PV_PHOTON_SORT_BLOCK records, the other stages in workgroups of
// PV_PHOTON_SORT_BLOCK invocations.
layout(local_size_x_id = 1) in;

layout(binding = PV_BINDING_PARAMS, scalar) readonly buffer ParamsBuffer { FrameParams paramsBuffer; };
// Copied from paramsBuffer before any branch, as in scene_access.glsl: llvmpipe loads a
// storage-buffer value inside a loop as a loop over the active lanes, and the histogram and the
// scatter read the sort shift and the block count once a record.
FrameParams params;
layout(binding = PV_BINDING_PHOTON_RECORDS, scalar) readonly buffer Records { PhotonRecord records[]; };
layout(binding = PV_BINDING_PHOTON_SORTED, scalar) writeonly buffer Sorted { PhotonRecord sortedRecords[]; };
layout(binding = PV_BINDING_PHOTON_SORT_A, scalar) buffer SortA { uvec2 sortA[]; };
layout(binding = PV_BINDING_PHOTON_SORT_B, scalar) buffer SortB { uvec2 sortB[]; };
layout(binding = PV_BINDING_PHOTON_BLOCK_COUNTS, scalar) buffer BlockCounts { uint blockCounts[]; };
layout(binding = PV_BINDING_PHOTON_CELLS, scalar) buffer Cells { uvec2 cells[]; };

shared uint sharedWords[PV_PHOTON_SCAN_GROUP];

uint recordCount() { return params.photonSortRecords; }
uint traceGroupCount() { return params.photonCount / PV_PHOTON_GROUP_SIZE; }
uint blockCount() { return recordCount() / PV_PHOTON_SORT_BLOCK; }

// Even passes sort A into B, odd ones B back into A.
bool evenPass() { return ((params.photonSortShift >> 3u) & 1u) == 0u; }
uvec2 sortInput(uint i) { return evenPass() ? sortA[i] : sortB[i]; }
void sortOutput(uint i, uvec2 v) {
    if (evenPass()) sortB[i] = v; else sortA[i] = v;
}
// Where the last pass left the pairs.
uvec2 sorted(uint i) { return (PV_PHOTON_SORT_PASSES & 1u) != 0u ? sortB[i] : sortA[i]; }
uint digitOf(uvec2 pair) {
    return (pair.x >> params.photonSortShift) & (PV_PHOTON_SORT_DIGITS - 1u);
}

// One invocation per block (histogram and scatter): it walks the block's records in order, so
// the histogram is plain additions and the scatter is stable without a rank per record.
void histogram() {
    uint block = gl_WorkGroupID.x;
    uint base = block * PV_PHOTON_SORT_BLOCK;
    for (uint d = 0u; d < PV_PHOTON_SORT_DIGITS; ++d) sharedWords[d] = 0u;
    for (uint i = 0u; i < PV_PHOTON_SORT_BLOCK; ++i)
        sharedWords[digitOf(sortInput(base + i))] += 1u;
    for (uint d = 0u; d < PV_PHOTON_SORT_DIGITS; ++d)
        blockCounts[d * blockCount() + block] = sharedWords[d];
}

// Exclusive scan of the 256 × blocks counts, digit-major: each entry becomes where that block's
// records of that digit start in the output. For the compaction: of the trace's groups' counts
// and the zero after them, which becomes the total.
void scan() {
    uint t = gl_LocalInvocationID.x;
    uint total = kStage == STAGE_COMPACT_SCAN ? traceGroupCount() + 1u
                                              : PV_PHOTON_SORT_DIGITS * blockCount();
    uint chunk = (total + PV_PHOTON_SCAN_GROUP - 1u) / PV_PHOTON_SCAN_GROUP;
    uint begin = min(t * chunk, total);
    uint end = min(begin + chunk, total);
    uint sum = 0u;
    for (uint i = begin; i < end; ++i) sum += blockCounts[i];
    sharedWords[t] = sum;
    barrier();
    if (t == 0u) {
        uint running = 0u;
        for (uint i = 0u; i < PV_PHOTON_SCAN_GROUP; ++i) {
            uint v = sharedWords[i];
            sharedWords[i] = running;
            running += v;
        }
    }
    barrier();
    uint running = sharedWords[t];
    for (uint i = begin; i < end; ++i) {
        uint v = blockCounts[i];
        blockCounts[i] = running;
        running += v;
    }
}

// Stable: the block's records of one digit go out in the order they come in, after those of the
// same digit in earlier blocks (the scanned counts).
void scatter() {
    uint block = gl_WorkGroupID.x;
    uint base = block * PV_PHOTON_SORT_BLOCK;
    for (uint d = 0u; d < PV_PHOTON_SORT_DIGITS; ++d)
        sharedWords[d] = blockCounts[d * blockCount() + block];
    for (uint i = 0u; i < PV_PHOTON_SORT_BLOCK; ++i) {
        uvec2 pair = sortInput(base + i);
        uint digit = digitOf(pair);
        sortOutput(sharedWords[digit], pair);
        sharedWords[digit] += 1u;
    }
}

// Slot i of trace_photons' output: its pair, if stored, moves to its group's offset in sort A;
// the slots after the total up to whole sort blocks get the empty key (sorted last, never
// looked up).
void compact() {
    uint i = gl_GlobalInvocationID.x;
    uint group = i / PV_PHOTON_GROUP_SLOTS;
    uint local = i - group * PV_PHOTON_GROUP_SLOTS;
    uint offset = blockCounts[group];
    if (local < blockCounts[group + 1u] - offset) sortA[offset + local] = sortB[i];
    uint total = blockCounts[traceGroupCount()];
    uint padded = (total + PV_PHOTON_SORT_BLOCK - 1u) / PV_PHOTON_SORT_BLOCK;
    padded *= PV_PHOTON_SORT_BLOCK;
    if (i >= total && i < padded) sortA[i] = uvec2(PV_PHOTON_EMPTY_KEY, 0u);
}

// After the last pass the pairs are in key order: copy the records into that order and mark
// where each bucket begins and ends (the host zeroed the cells).
void buildCells() {
    uint i = gl_GlobalInvocationID.x;
    uint n = recordCount();
    if (i >= n) return;
    uvec2 pair = sorted(i);
    sortedRecords[i] = records[pair.y];
    if (pair.x == PV_PHOTON_EMPTY_KEY) return;
    if (i == 0u || sorted(i - 1u).x != pair.x) cells[pair.x].x = i;
    if (i + 1u == n || sorted(i + 1u).x != pair.x) cells[pair.x].y = i + 1u;
}

void main() {
    params = paramsBuffer;  // before any branch (above)
    if (kStage == STAGE_HISTOGRAM) histogram();
    else if (kStage == STAGE_SCAN || kStage == STAGE_COMPACT_SCAN) scan();
    else if (kStage == STAGE_SCATTER) scatter();
    else if (kStage == STAGE_COMPACT) compact();
    else buildCells();
}
