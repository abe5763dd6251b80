#!/usr/bin/env bash
# `dlgs play` side by side: this build against another `dlgs` binary (e.g. one built from an
# older commit), runs interleaved, on the two files of issue 55:
#   - the 273k-Gaussian 5-GOP stream (CSOG high, RNTC, HEVC, language) at 30 fps:
#     shown / dropped, time to first frame, peak RSS;
#   - 80k dynamic + language (the plant, 5 intra GOPs, HEVC) at --max-speed --language:
#     frames shown per wall second, time to first frame, GOP decode.
# The files are SYNTHETIC motion on real scenes (no trained DLGStream model exists here):
# target/play-273k.dlgs from `cargo run --release -p dlgs-decoder --example play_file`,
# target/max80k.dlgs from `dlgs synth ../shared/data/splat/marcelpadilla_plant.splat
# -o target/max80k.dlgs --dynamic-fraction 0.75 --max-dynamic 80000 --language --gops 5`.
#   scripts/play_bench.sh OLD_DLGS [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
old=${1:?usage: scripts/play_bench.sh OLD_DLGS [RUNS]}
runs=${2:-3}
cargo build --release -q -p dlgs-cli
new=target/release/dlgs
[ -f target/play-273k.dlgs ] || cargo run --release -q -p dlgs-decoder --example play_file
[ -f target/max80k.dlgs ] || $new synth ../shared/data/splat/marcelpadilla_plant.splat \
  -o target/max80k.dlgs --dynamic-fraction 0.75 --max-dynamic 80000 --language --gops 5 >/dev/null
summary() { # JSON report + `time -v` output -> one table row
  python3 - "$1" "$2" "$3" <<'EOF'
import json, re, sys
rep = json.load(open(sys.argv[1]))
rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", open(sys.argv[2]).read())
gops = ", ".join("%.0f" % m for m in rep["gop_decode_ms"])
wall_fps = rep.get("wall_fps") or (rep["shown"] / rep["wall_s"] if rep["wall_s"] else 0)
print("| %s | %d / %d | %.0f ms | %.1f | %s ms | %.0f MB |" % (
    sys.argv[3], rep["shown"], rep["dropped"], rep["time_to_first_frame_ms"], wall_fps, gops,
    int(rss.group(1)) / 1024 if rss else 0))
EOF
}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "load before: $(uptime | sed 's/.*load average: //')"
for file in "target/play-273k.dlgs" "target/max80k.dlgs --max-speed --language"; do
  echo
  echo "### dlgs play $file"
  echo "| build | shown / dropped | first frame | shown per wall second | GOP decode | peak RSS |"
  echo "|---|---|---|---|---|---|"
  for r in $(seq "$runs"); do
    for which in new old; do
      bin=$new; [ $which = old ] && bin=$old
      # shellcheck disable=SC2086
      /usr/bin/time -v "$bin" play $file --json >"$tmp/rep.json" 2>"$tmp/time.txt"
      summary "$tmp/rep.json" "$tmp/time.txt" "$which, run $r"
    done
  done
done
echo
echo "load after: $(uptime | sed 's/.*load average: //')"
