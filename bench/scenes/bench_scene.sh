# Sourced by bench/compare_blender.sh, bench/ablation.sh and bench/gpu_time.sh: the benchmark
# scenes by name, and the cache key of a reference rendered of one. Needs $root set.

# The shared data beside the checkout, else where PREVIS_DATA_DIR says; the cache of references
# and generated scenes.
data=${PREVIS_DATA_DIR:-${PREVIS_SHARED_DATA:-$root/../shared/data}}
env_map="$data/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr"
cache="$root/build/compare_blender"
mkdir -p "$cache"

# Sets $scene (a glTF), $env (an HDR map, or "none") and $previs_args (extra `previs render`
# options) for scene $1: bunny, dragon or area-lights.
bench_scene() {
    previs_args=()
    case "$1" in
        bunny)
            scene="$cache/bunny.gltf"
            [[ -f "$scene" ]] || python3 "$root/bench/scenes/make_scenes.py" bunny "$data" "$scene"
            env=$env_map ;;
        dragon)
            # The throughput benchmark's 810K-triangle case (make_scenes.py dragon).
            scene="$cache/dragon.gltf"
            [[ -f "$scene" ]] || python3 "$root/bench/scenes/make_scenes.py" dragon "$data" "$scene"
            env=$env_map ;;
        area-lights)
            scene="$root/bench/scenes/area_lights_mirror.gltf"
            # These benchmarks compare path tracers. The mirror sphere under small lights would
            # switch on photon mapping (--photons auto, issue 9): another, consistent but biased
            # estimator, which Cycles does not have.
            previs_args=(--photons off)
            env=none ;;
        *) echo "unknown scene $1 (bunny, dragon, area-lights)" >&2; return 2 ;;
    esac
}

# The key under which a reference of scene file $1 with map $2 at $3×$4, depth $5, $6 spp is
# cached: the scene's bytes and the settings (with bench_scene's $previs_args).
bench_reference_key() {
    { cat "$1"; echo "$2 $3 $4 $5 $6 ${previs_args[*]}"; } | sha256sum | cut -c1-16
}
