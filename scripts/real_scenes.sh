# The real scenes of ../shared/data that the issue-5 comparisons run on, smallest first (paths
# under $DATA). Sourced by scripts/peers.sh, canonical_rd.sh and spz_match.sh.
SCENES=(
  ply/gs3d-fork_lod3_tile_0_1971_sh3.ply
  ply/supersplat_fruit_drops_minimal_4721_sh3.ply
  ply/gs3d-fork_lod2_tile_0_6831_sh3.ply
  ply/gs3d-fork_lod1_tile_0_0.5x_14051_sh3.ply
  ply/gsplat_DATA_new_22589_sh3.ply
  ply/v3dg_donut_mipsplatting_45624_sh0.ply
  splat/marcelpadilla_plant.splat
  sequence/playcanvas_wave_200f/wave_0001.sog
)
# DLGS_SCENES="a.ply b.splat": run on these instead (relative to $DATA, or absolute), e.g. the
# larger scene built from the real ones (scripts/large_scene_rd.sh).
if [ -n "${DLGS_SCENES:-}" ]; then read -r -a SCENES <<< "$DLGS_SCENES"; fi
# scene_path S: the file of scene S. dlgs reads the wave sequence's SOG frames itself (bit for bit
# as splat-transform decodes them: tests/tests/interop.rs).
scene_path() {
  case "$1" in /*) echo "$1" ;; *) echo "$DATA/$1" ;; esac
}
# scene_count FILE: its Gaussians (a PLY's vertex count; a .splat is 32 bytes per Gaussian; a
# SOG's meta.json count).
scene_count() {
  case "$1" in
    *.splat) echo $(( $(stat -c %s "$1") / 32 )) ;;
    *.sog) python3 -c 'import json, sys, zipfile; print(json.loads(zipfile.ZipFile(sys.argv[1]).read("meta.json"))["count"])' "$1" ;;
    *) head -c 4096 "$1" | tr -d '\r' | awk '/^element vertex/ {print $3; exit}' ;;
  esac
}
