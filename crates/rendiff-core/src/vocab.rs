//! rendiff's vocabulary: the words scene files, manifest.json, results.json
//! and the baseline use for features, statuses, buffers and mismatch
//! classes, each spelled once here. The Python harness reads the same words
//! from `rendiff vocab --json` (its `vocab.py` mirrors them and a test fails
//! if the two drift), so a renamed status or a new feature cannot be known
//! to one side only.
//!
//! The rules that belong to a word live beside it: which features need
//! shading, which statuses turn a run red.

use serde::{Deserialize, Serialize};

macro_rules! words {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $s:literal),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
        pub enum $name {
            $($(#[$vm])* #[serde(rename = $s)] $v),+
        }

        impl $name {
            /// Every value, in the order the docs list them.
            pub const ALL: &'static [$name] = &[$($name::$v),+];

            /// The spelling in files and records.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$v => $s),+
                }
            }

            /// The value spelled `s`; `None` for anything else.
            pub fn parse(s: &str) -> Option<$name> {
                Self::ALL.iter().copied().find(|x| x.as_str() == s)
            }

            /// Every spelling, for messages and `rendiff vocab`.
            pub fn names() -> Vec<&'static str> {
                Self::ALL.iter().map(|x| x.as_str()).collect()
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

words! {
    /// What a scene requires of a renderer (`requires = [...]`): a backend
    /// runs a buffer only when it models every feature that buffer needs.
    Feature {
        /// Planar depth `Z`.
        Depth = "depth",
        /// `id.prim` and `id.object`.
        Ids = "ids",
        /// Geometric normals `N`.
        Normals = "normals",
        /// Emissive surfaces.
        Emission = "emission",
        /// Lambertian reflection.
        Lambert = "lambert",
        /// Point lights.
        PointLight = "point_light",
        /// Directional lights.
        DirectionalLight = "directional_light",
        /// Shadow rays toward lights.
        Shadows = "shadows",
        /// Area lights.
        AreaLight = "area_light",
        /// Path tracing (indirect light).
        GlobalIllumination = "global_illumination",
        /// Both faces shade (normal turned to the viewer).
        TwoSided = "two_sided",
        /// Only the front face shades.
        OneSided = "one_sided",
        /// Lights without shadow rays.
        Shadowless = "shadowless",
    }
}

impl Feature {
    /// The features the visibility buffers (Z, id, N) need: a backend that
    /// models these is compared on visibility on every scene.
    pub const VISIBILITY: &'static [Feature] = &[Feature::Depth, Feature::Ids, Feature::Normals];

    /// Features that make a scene ask for radiance at all.
    pub const SHADED: &'static [Feature] = &[
        Feature::Lambert,
        Feature::Emission,
        Feature::GlobalIllumination,
    ];
}

/// True when a scene requiring `requires` asks for radiance: the one place
/// that decides whether anything is shaded.
pub fn needs_shading<'a>(requires: impl IntoIterator<Item = &'a str>) -> bool {
    requires
        .into_iter()
        .any(|r| Feature::SHADED.iter().any(|f| f.as_str() == r))
}

words! {
    /// A verdict's status in results.json and the baseline.
    Status {
        /// Within the conventions.
        Pass = "pass",
        /// A renderer is wrong.
        Fail = "fail",
        /// Not compared (a missing feature or backend).
        Skipped = "skipped",
        /// The comparison could not be made (crash, timeout, unreadable buffer).
        Error = "error",
        /// A known divergence within its recorded bound.
        ExpectedFail = "expected_fail",
        /// A known divergence that went away: update the expectation.
        UnexpectedPass = "unexpected_pass",
    }
}

impl Status {
    /// True for statuses that turn a run red: the one place that says so.
    pub fn is_bad(self) -> bool {
        matches!(self, Status::Fail | Status::Error | Status::UnexpectedPass)
    }
}

words! {
    /// What happened to one render in manifest.json.
    RenderStatus {
        /// Buffers written.
        Ok = "ok",
        /// Not rendered, with a reason (missing features, renderer not installed).
        Skipped = "skipped",
        /// The renderer failed (crash, timeout, no output).
        Error = "error",
    }
}

/// A render record is an error until its renderer's outcome says otherwise,
/// so a record that no branch filled in never reads as a success.
impl Default for RenderStatus {
    fn default() -> Self {
        RenderStatus::Error
    }
}

words! {
    /// What a verdict compares (`buffer` in results.json).
    Buffer {
        /// `id.prim` and `id.object`.
        Id = "id",
        /// Planar depth.
        Z = "Z",
        /// Geometric normals.
        N = "N",
        /// Radiance.
        Rgb = "RGB",
        /// The backend's camera, measured on the calibration probes.
        Camera = "camera",
        /// The scene itself could not be loaded or resolved.
        Scene = "scene",
        /// rendiff's resolved triangles against an independent decode of the
        /// scene's mesh files (backend: the decoder's name).
        Import = "import",
    }
}

words! {
    /// The verifier's class of one ID mismatch (docs/verifier.md).
    MismatchClass {
        /// Within rounding distance of an edge the two triangles share: allowed.
        Edge = "edge",
        /// Both triangles cover the center at equal depth: allowed.
        Tie = "tie",
        /// A leak through a closed edge: fails unless the backend declares it.
        Crack = "crack",
        /// Anything else: a renderer is wrong.
        Interior = "interior",
    }
}

/// The exit status of a render that was *skipped* (the renderer cannot model
/// what the scene needs, or cannot run here, e.g. no Vulkan adapter), as
/// opposed to 0 (rendered) and any other status (failed): `rendiff render`,
/// the harness's `render` and every command renderer (docs/your-renderer.md)
/// speak it.
pub const EXIT_SKIPPED: i32 = 3;

/// Format tag of a run's manifest.json (written by `check` and `merge`, read
/// by the harness's comparison and by `merge`).
pub const MANIFEST_FORMAT: &str = "rendiff-manifest/1";

/// Format tag of a run's results.json (written by the harness's comparison,
/// read by `gate`, `bless` and `report`, which refuse any other).
pub const RESULTS_FORMAT: &str = "rendiff-results/1";

/// The whole vocabulary as JSON (`rendiff vocab --json`), for the harness's
/// drift test.
pub fn json() -> serde_json::Value {
    let names = |v: &[Feature]| v.iter().map(|f| f.as_str()).collect::<Vec<_>>();
    serde_json::json!({
        "features": Feature::names(),
        "visibility_features": names(Feature::VISIBILITY),
        "shaded_features": names(Feature::SHADED),
        "statuses": Status::names(),
        "failing_statuses": Status::ALL.iter().filter(|s| s.is_bad()).map(|s| s.as_str()).collect::<Vec<_>>(),
        "render_statuses": RenderStatus::names(),
        "buffers": Buffer::names(),
        "mismatch_classes": MismatchClass::names(),
        "exit_skipped": EXIT_SKIPPED,
        "manifest_format": MANIFEST_FORMAT,
        "results_format": RESULTS_FORMAT,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spellings_round_trip_through_serde_and_parse() {
        for &s in Status::ALL {
            let j = serde_json::to_string(&s).unwrap();
            assert_eq!(j, format!("\"{}\"", s.as_str()));
            assert_eq!(serde_json::from_str::<Status>(&j).unwrap(), s);
            assert_eq!(Status::parse(s.as_str()), Some(s));
        }
        assert_eq!(Buffer::parse("RGB"), Some(Buffer::Rgb));
        assert_eq!(Feature::parse("nope"), None);
    }

    #[test]
    fn shading_is_decided_by_the_shaded_features_only() {
        assert!(!needs_shading(["depth", "ids", "shadows"]));
        assert!(needs_shading(["depth", "lambert"]));
        assert!(needs_shading(["global_illumination"]));
        assert!(Feature::VISIBILITY
            .iter()
            .all(|f| !Feature::SHADED.contains(f)));
    }
}
