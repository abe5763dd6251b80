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
# scene_path S: the file of scene S. A SOG frame (the wave sequence, PlayCanvas SOG v2) is read
# through its PLY, which `@playcanvas/splat-transform` writes once into target/sog_scenes/ (dlgs
# reads PLY, .splat and SPZ): that PLY is the scene the comparisons start from.
scene_path() {
  local path
  case "$1" in /*) path=$1 ;; *) path=$DATA/$1 ;; esac
  case "$path" in *.sog) sog_ply "$path" ;; *) echo "$path" ;; esac
}
# sog_ply FILE.sog: the PLY of a SOG file, written by splat-transform on first use.
sog_ply() {
  local out
  out="target/sog_scenes/$(basename "${1%.sog}").ply"
  if [ ! -f "$out" ]; then
    mkdir -p target/sog_scenes
    npx -y @playcanvas/splat-transform@2.7.1 -q -w "$1" "$out" >&2
  fi
  echo "$out"
}
# scene_count FILE: its Gaussians (a PLY's vertex count; a .splat is 32 bytes per Gaussian).
scene_count() {
  case "$1" in
    *.splat) echo $(( $(stat -c %s "$1") / 32 )) ;;
    *) head -c 4096 "$1" | tr -d '\r' | awk '/^element vertex/ {print $3; exit}' ;;
  esac
}
