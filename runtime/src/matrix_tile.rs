//! `VKDIFF_MATRIX_TILE`: the workgroup tile of the matrix-unit GEMM and convolution.

use crate::error::{Error, Result};
use crate::matrix_units::Fragment;

/// How many subgroups share a workgroup's tile in `gemm_coop` and `conv_coop`
/// (kernels/src/spec.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatrixTile {
    /// Unset or `auto`: the tiles measured fastest so far, four subgroups (2×2 or 4×4
    /// fragments each: 64×64 or 128×128 at 16×16×16), until a GPU shows eight faster.
    Auto,
    /// `4`: four subgroups in a 2×2 grid, as `auto` chooses their fragments.
    Four,
    /// `8`: eight subgroups in a 2×4 grid of 4×2 fragments, K-steps of two fragments (128×128 at
    /// 16×16×16), where such a variant is built for the device's fragment (else as `4`).
    Eight,
}

impl MatrixTile {
    pub fn from_env() -> Result<MatrixTile> {
        match std::env::var("VKDIFF_MATRIX_TILE") {
            Err(_) => Ok(MatrixTile::Auto),
            Ok(value) => MatrixTile::parse(&value),
        }
    }

    pub fn parse(value: &str) -> Result<MatrixTile> {
        match value.trim().to_ascii_lowercase().as_str() {
            "auto" | "" => Ok(MatrixTile::Auto),
            "4" => Ok(MatrixTile::Four),
            "8" => Ok(MatrixTile::Eight),
            _ => Err(Error::BadSetting(format!(
                "VKDIFF_MATRIX_TILE={value}: use 4 (four subgroups a workgroup), 8 (eight, 128×128 tiles of \
                 16×16×16 fragments) or auto (the default)"
            ))),
        }
    }

    /// Whether products take the eight-subgroup tiles where one is built.
    pub fn eight_subgroups(self) -> bool {
        self == MatrixTile::Eight
    }
}

/// Whether eight-subgroup variants are built for fragment `f` (all but AMD's 64 lanes).
pub fn eight_subgroups_built(f: &Fragment) -> bool {
    let want: Vec<(&str, u32)> = f.params().into_iter().chain([("GN", 4)]).collect();
    vkdiff_kernels::find("gemm_coop", vkdiff_kernels::Dtype::F16, &want).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_setting_names_subgroups_a_workgroup() {
        for (value, tile) in
            [("", MatrixTile::Auto), ("AUTO", MatrixTile::Auto), (" 4", MatrixTile::Four), ("8", MatrixTile::Eight)]
        {
            assert_eq!(MatrixTile::parse(value).unwrap(), tile, "{value:?}");
        }
        assert!(MatrixTile::Eight.eight_subgroups() && !MatrixTile::Auto.eight_subgroups());
        let fragment = |m, n, k, lanes| Fragment { m, n, k, lanes, flexible: false };
        assert!(eight_subgroups_built(&fragment(16, 16, 16, 32)) && eight_subgroups_built(&fragment(8, 8, 8, 8)));
        assert!(!eight_subgroups_built(&fragment(16, 16, 16, 64)), "AMD's 64 lanes reach 128×128 with four");
        let err = MatrixTile::parse("128").unwrap_err().to_string();
        assert!(err.starts_with("VKDIFF_MATRIX_TILE=128: use 4"), "{err}");
    }
}
