"""Sorts perf samples of llvmpipe's JIT code by kind of machine code (bench/profile_jit.sh).

  profile_jit.py range IPS            first sampled address of the JIT code, and how many
                                      instructions to disassemble from there
  profile_jit.py classify IPS CODE    the share of samples per kind, and the hottest other chunks

The kinds are recognised by the code gallivm (Mesa 22.3) emits for them:
- texel fetch: a function per texel buffer, called per fetch, starting with a bounds compare
  against the buffer's size (`vpcmpltd OFFSET(%rdi){1to8}`) and ending in `ret`;
- per-lane array store: a store to a stack slot indexed per lane, behind a test of the lane's mask
  bit (a local array indexed per lane, e.g. a traversal stack);
- uniform load lane loop: an 8-iteration loop that broadcasts a load (a storage-buffer load inside
  a branch or loop);
- integer division: `div` (integer / and % are scalar, lane by lane).
"""
import bisect
import collections
import re
import sys


def read_ips(path):
    return [int(line, 16) for line in open(path) if line.strip()]


def hottest_range(ips):
    # The sampled addresses split where more than 256 KiB lie between two of them; the cluster
    # with the most samples is the shader's code.
    counts = collections.Counter(ips)
    clusters = []
    for ip in sorted(counts):
        if clusters and ip - clusters[-1][1] <= 256 * 1024:
            clusters[-1][1] = ip
            clusters[-1][2] += counts[ip]
        else:
            clusters.append([ip, ip, counts[ip]])
    first, last, _ = max(clusters, key=lambda c: c[2])
    # At most one instruction per byte.
    return first, last - first + 64


def read_code(path):
    code = []
    for line in open(path):
        m = re.match(r"\s+(0x[0-9a-f]+):\s*(.*)", line)
        if m:
            code.append((int(m.group(1), 16), m.group(2)))
    return code


def classify(ips, code):
    texel = [False] * len(code)
    i = 0
    while i < len(code):
        if re.match(r"vpcmpltd 0x[0-9a-f]+\(%rdi\)\{1to8\}", code[i][1]):
            j = i
            while j < len(code) and not code[j][1].startswith("ret"):
                texel[j] = True
                j += 1
            if j < len(code):
                texel[j] = True
            i = j
        i += 1

    def kind(k):
        if texel[k]:
            return "texel fetch"
        window = " | ".join(t for _, t in code[max(0, k - 6):k + 7])
        if re.search(r"cmp\s+\$0x8,%e", window) and "vpbroadcastd" in window:
            return "uniform load lane loop"
        if re.search(r"mov\s+%e..,0x[0-9a-f]+\(%rsp,%r..,4\)", window) and "test   $0x1" in window:
            return "per-lane array store"
        if re.search(r"\bdiv\b", window):
            return "integer division"
        return "other"

    addresses = [a for a, _ in code]
    kinds = collections.Counter()
    chunks = collections.Counter()
    for ip in ips:
        if not addresses or ip < addresses[0] or ip > addresses[-1]:
            kinds["outside the disassembled JIT code"] += 1
            continue
        k = bisect.bisect_right(addresses, ip) - 1
        name = kind(k)
        kinds[name] += 1
        if name == "other":
            chunks[addresses[k] // 128 * 128] += 1
    n = len(ips)
    print(f"{n} samples")
    print("| kind | share of samples |")
    print("|---|---|")
    for name, count in kinds.most_common():
        print(f"| {name} | {100 * count / n:.1f} % |")
    print("hottest 128-byte chunks of the rest:", ", ".join(
        f"{chunk:x} {100 * count / n:.1f} %" for chunk, count in chunks.most_common(8)))


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "range":
        first, size = hottest_range(read_ips(sys.argv[2]))
        print(f"{first:x} {size}")
    elif len(sys.argv) == 4 and sys.argv[1] == "classify":
        classify(read_ips(sys.argv[2]), read_code(sys.argv[3]))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
