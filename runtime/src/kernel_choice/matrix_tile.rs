//! `VKDIFF_MATRIX_TILE` ([`crate::Settings::matrix_tile`]): the workgroup tile of the matrix-unit GEMM and convolution.

use crate::kernel_choice::matrix_units::Fragment;

/// How many subgroups share a workgroup's tile in `gemm_coop` and `conv_coop`, and in what grid
/// (kernels/src/spec_cooperative.rs). The eight-subgroup tiles are named by their size at 16×16×16
/// fragments (half each side at lavapipe's 8×8×8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatrixTile {
    /// Unset or `auto`: the tiles measured fastest so far, four subgroups (2×2 or 4×4
    /// fragments each: 64×64 or 128×128 at 16×16×16), until a GPU shows eight faster.
    Auto,
    /// `4`: four subgroups in a 2×2 grid, as `auto` chooses their fragments.
    Four,
    /// `8` or `128x128`: eight subgroups in a 2×4 grid of 4×2 fragments, K-steps of two
    /// fragments, where such a variant is built for the device's fragment (else as `4`).
    Eight,
    /// `128x64`: eight subgroups in a 4×2 grid of 2×2 fragments (the tile that divides SDXL's 320
    /// channels), K-steps of two, where built (else as `4`).
    EightTall,
    /// `64x128`: eight subgroups in a 2×4 grid of 2×2 fragments, K-steps of two, where built
    /// (else as `4`).
    EightWide,
}

/// An eight-subgroup tile's grid of subgroups and fragments a subgroup: GM, GN, WM and WN in
/// kernels/src/spec_cooperative.rs.
pub type SubgroupGrid = [(&'static str, u32); 4];

impl MatrixTile {
    /// The eight-subgroup tiles, as the tuner tries them.
    pub const EIGHT_SUBGROUPS: [MatrixTile; 3] = [MatrixTile::Eight, MatrixTile::EightTall, MatrixTile::EightWide];

    /// What `VKDIFF_MATRIX_TILE` takes.
    pub const VALUES: &'static str = "4 (four subgroups a workgroup), 8 or 128x128 (eight, 128×128 tiles of 16×16×16 \
                                      fragments), 128x64, 64x128 (eight, those tiles) or auto (the default)";

    /// A tile as [`MatrixTile::name`] spells it (any case, `128x128` for `8`); None for anything else.
    pub fn parse(value: &str) -> Option<MatrixTile> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Some(MatrixTile::Auto),
            "4" => Some(MatrixTile::Four),
            "8" | "128x128" => Some(MatrixTile::Eight),
            "128x64" => Some(MatrixTile::EightTall),
            "64x128" => Some(MatrixTile::EightWide),
            _ => None,
        }
    }

    /// The grid of an eight-subgroup tile; None for the four-subgroup settings.
    pub fn eight_subgroup_grid(self) -> Option<SubgroupGrid> {
        let grid = |gm, gn, wm, wn| Some([("GM", gm), ("GN", gn), ("WM", wm), ("WN", wn)]);
        match self {
            MatrixTile::Auto | MatrixTile::Four => None,
            MatrixTile::Eight => grid(2, 4, 4, 2),
            MatrixTile::EightTall => grid(4, 2, 2, 2),
            MatrixTile::EightWide => grid(2, 4, 2, 2),
        }
    }

    /// How `VKDIFF_MATRIX_TILE` spells this setting.
    pub fn name(self) -> &'static str {
        match self {
            MatrixTile::Auto => "auto",
            MatrixTile::Four => "4",
            MatrixTile::Eight => "8",
            MatrixTile::EightTall => "128x64",
            MatrixTile::EightWide => "64x128",
        }
    }

    /// Whether products take an eight-subgroup tile where one is built.
    pub fn eight_subgroups(self) -> bool {
        self.eight_subgroup_grid().is_some()
    }

    /// Whether this setting's eight-subgroup tile is built for fragment `f`.
    pub fn built_for(self, f: &Fragment) -> bool {
        self.eight_subgroup_grid().is_some_and(|grid| {
            let want: Vec<(&str, u32)> = f.params().into_iter().chain(grid).collect();
            vkdiff_kernels::find("gemm_coop", vkdiff_kernels::Dtype::F16, &want).is_some()
        })
    }
}

/// The line a run prints where `tile` asks for an eight-subgroup tile that is not built for the
/// fragment its matrix units take (`fragment`; None where its products do not run on them): its
/// products then take four subgroups, as they would unasked.
pub(crate) fn unbuilt_tile_note(tile: MatrixTile, device: &str, fragment: Option<Fragment>) -> Option<String> {
    let f = fragment.filter(|f| tile.eight_subgroups() && !tile.built_for(f))?;
    Some(format!(
        "VKDIFF_MATRIX_TILE={}: no such tile is built for {} fragments at {} lanes (`{device}`); its matrix units \
         keep four subgroups a workgroup",
        tile.name(),
        f.shape(),
        f.lanes
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setting_names_subgroups_a_workgroup() {
        for (value, tile) in [
            ("", MatrixTile::Auto),
            ("AUTO", MatrixTile::Auto),
            (" 4", MatrixTile::Four),
            ("8", MatrixTile::Eight),
            ("128X128", MatrixTile::Eight),
            ("128x64", MatrixTile::EightTall),
            ("64x128", MatrixTile::EightWide),
        ] {
            assert_eq!(MatrixTile::parse(value), Some(tile), "{value:?}");
            assert_eq!(MatrixTile::parse(tile.name()), Some(tile), "{tile:?}");
        }
        assert!(MatrixTile::Eight.eight_subgroups() && !MatrixTile::Auto.eight_subgroups());
        let fragment = |m, n, k, lanes| Fragment { m, n, k, lanes, flexible: false };
        let (nvidia, lavapipe, amd) = (fragment(16, 16, 16, 32), fragment(8, 8, 8, 8), fragment(16, 16, 16, 64));
        for tile in MatrixTile::EIGHT_SUBGROUPS {
            assert!(tile.built_for(&nvidia) && tile.built_for(&lavapipe), "{tile:?}");
            assert!(!tile.built_for(&amd), "{tile:?}: AMD's 64 lanes reach 128×128 with four");
        }
        assert!(!MatrixTile::EightTall.built_for(&fragment(8, 16, 16, 16)), "128×64 for NVIDIA's and lavapipe's only");
        assert!(MatrixTile::Eight.built_for(&fragment(8, 16, 16, 16)), "128×128 for Intel's too");
        assert_eq!(MatrixTile::parse("128"), None);
    }

    #[test]
    fn an_eight_subgroup_tile_not_built_for_the_fragment_is_named() {
        let fragment = |m, n, k, lanes| Some(Fragment { m, n, k, lanes, flexible: false });
        let intel = fragment(8, 16, 16, 16);
        let note = unbuilt_tile_note(MatrixTile::EightTall, "Arc", intel).unwrap();
        assert_eq!(
            note,
            "VKDIFF_MATRIX_TILE=128x64: no such tile is built for 8×16×16 fragments at 16 lanes (`Arc`); its matrix \
             units keep four subgroups a workgroup"
        );
        assert_eq!(unbuilt_tile_note(MatrixTile::Eight, "Arc", intel), None, "128×128 is built for Intel's");
        assert_eq!(unbuilt_tile_note(MatrixTile::EightTall, "H200", fragment(16, 16, 16, 32)), None);
        assert_eq!(unbuilt_tile_note(MatrixTile::Auto, "Arc", intel), None);
        assert_eq!(unbuilt_tile_note(MatrixTile::EightTall, "llvmpipe", None), None, "no matrix units");
    }

    #[test]
    fn eight_subgroup_grids_hold_eight_subgroups_of_the_sizes_they_are_named_by() {
        for (tile, size) in
            [(MatrixTile::Eight, (128, 128)), (MatrixTile::EightTall, (128, 64)), (MatrixTile::EightWide, (64, 128))]
        {
            let [(_, gm), (_, gn), (_, wm), (_, wn)] = tile.eight_subgroup_grid().unwrap();
            assert_eq!((gm * gn, (gm * wm * 16, gn * wn * 16)), (8, size), "{tile:?}");
        }
        assert_eq!(MatrixTile::Four.eight_subgroup_grid(), None);
    }
}
