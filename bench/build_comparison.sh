# Sourced by bench/gpu_time.sh and bench/start_time.sh, which compare previs builds on named
# workloads: their shared options and the median of their runs.

# Parses "[--runs N] [--only WORKLOAD,...] PREVIS_BINARY..." into $runs (kept when not given),
# $workloads (all of $known when not given; each checked against $known) and $binaries.
parse_build_comparison_options() {
    local usage="usage: $0 [--runs N] [--only WORKLOAD,...] PREVIS_BINARY..."
    workloads=("${known[@]}")
    while [[ $# -gt 0 && $1 == --* ]]; do
        case "$1" in
            --runs) runs=$2; shift 2 ;;
            --only) IFS=, read -r -a workloads <<<"$2"; shift 2 ;;
            *) echo "$usage" >&2; exit 2 ;;
        esac
    done
    (($# > 0)) || { echo "$usage" >&2; exit 2; }
    binaries=("$@")
    ((${#workloads[@]})) || { echo "$0: --only needs a workload (${known[*]})" >&2; exit 2; }
    local w
    for w in "${workloads[@]}"; do
        [[ " ${known[*]} " == *" $w "* ]] ||
            { echo "$0: unknown workload '$w' (${known[*]})" >&2; exit 2; }
    done
}

# The median of the numbers on standard input, one a line.
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
