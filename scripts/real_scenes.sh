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
)
