//! Failures of a fuzz run, grouped into findings by signature, and the
//! ledger `FOLDER/findings.json` (format in docs/fuzzing.md).
//!
//! A failure is one failing verdict of results.json (fail, error or
//! unexpected pass) on a generated scene; its class is what the verifier
//! counted ([`failure_class`]). Failures are grouped in two steps: by
//! (backend, buffer, class) ([`group`]), then each group by the geometric
//! situation (`situation.rs`) of its reduced scene ([`split`]): the smallest
//! scene is reduced, the scenes whose own geometry has every tag of the
//! reduced scene's situation join it, and the rest are split the same way.
//! Two failures with the same signature (backend, buffer, class, situation)
//! are presumed one cause: the finding keeps every scene that hit it and
//! counts them by grammar family. The signature is what a known-finding
//! declaration matches (`known.rs`).

use crate::gate::{Status, Verdict};
use serde::Serialize;
use std::collections::BTreeMap;

/// Format tag of findings.json.
pub const FINDINGS_FORMAT: &str = "rendiff-findings/1";

/// The class of a failing verdict, in the verifier's words: the first of
/// `interior`, `crack`, `mask` whose count is not zero (in that order: an
/// interior mismatch is a bug whatever else happened), else what the
/// buffer's own judge failed on (`depth` for Z, `normal` for N, `radiance`
/// for RGB, `camera` for a calibration probe); `error` and
/// `unexpected_pass` for those statuses. None for a verdict that passed.
pub fn failure_class(v: &Verdict) -> Option<String> {
    match v.status {
        Status::Error => return Some("error".into()),
        Status::UnexpectedPass => return Some("unexpected_pass".into()),
        s if !s.is_bad() => return None,
        _ => {}
    }
    for (count, class) in [
        ("interior_mismatches", "interior"),
        ("crack_mismatches", "crack"),
        ("mask_mismatches", "mask"),
    ] {
        if v.counts.get(count).is_some_and(|&n| n > 0) {
            return Some(class.into());
        }
    }
    Some(
        match v.buffer.as_str() {
            "Z" => "depth",
            "N" => "normal",
            "RGB" => "radiance",
            "camera" => "camera",
            _ => "other",
        }
        .into(),
    )
}

/// One failing verdict on one generated scene.
#[derive(Debug, Clone, Serialize)]
pub struct Failure {
    /// Scene name (file stem in FOLDER/scenes).
    pub scene: String,
    /// Backend.
    pub backend: String,
    /// Buffer.
    pub buffer: String,
    /// [`failure_class`].
    pub class: String,
    /// The verdict's reason (clipped).
    pub reason: String,
}

/// What groups failures into one finding.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub struct Signature {
    /// Backend.
    pub backend: String,
    /// Buffer.
    pub buffer: String,
    /// [`failure_class`].
    pub class: String,
    /// The situation tags (`situation.rs`, sorted) of the finding's reduced
    /// scene, else of its smallest scene (not reduced, or the reduction
    /// failed); empty after [`group`], set by [`split`].
    pub situation: Vec<String>,
}

/// A reduced repro, as findings.json records it.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ReducedRecord {
    /// The scene it was reduced from (a generated scene's name in findings.json).
    pub from: String,
    /// The standalone scene, relative to FOLDER.
    pub scene: String,
    /// The one command that reproduces the failure from it.
    pub command: String,
    /// Triangles, objects and bytes before and after.
    pub triangles_before: usize,
    /// (see above)
    pub triangles_after: usize,
    /// (see above)
    pub objects_before: usize,
    /// (see above)
    pub objects_after: usize,
    /// Lights before and after (a shaded scene's; both 0 and not written
    /// for a visibility scene).
    #[serde(skip_serializing_if = "is_zero")]
    pub lights_before: usize,
    /// (see above)
    #[serde(skip_serializing_if = "is_zero")]
    pub lights_after: usize,
    /// (see above)
    pub bytes_before: usize,
    /// (see above)
    pub bytes_after: usize,
    /// Image width and height before and after (the image step's crop).
    pub image_before: [u32; 2],
    /// (see above)
    pub image_after: [u32; 2],
    /// Why the image was kept, when the image step tried crops and none
    /// still failed (a crop rounds every ray anew).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub image_note: String,
    /// Check runs the reduction took, and candidate scenes in them.
    pub check_runs: usize,
    /// (see above)
    pub candidates: usize,
    /// False when the budget ran out before a fixed point.
    pub complete: bool,
    /// The triangles (indices in the scene it was reduced from) the
    /// failure's pixels were on, which every step stayed near (`near.rs`);
    /// absent when the verifier names none (no explanations: a side
    /// without `id.prim`, an error) and the step was held to the class alone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure_triangles: Option<Vec<usize>>,
    /// The failure's size at the start (an RGB failure's largest interior
    /// error), which every step stayed comparable to (`reduce.rs`,
    /// `SIZE_FRACTION`); absent when its entry records none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure_size: Option<f64>,
    /// Why there is no reduced scene, when reduction failed.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub error: String,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl ReducedRecord {
    /// Its sizes before and after, with `arrow` between, and what the
    /// reduction took: the one wording of the CLI's line and the page's.
    pub fn sizes(&self, arrow: &str) -> String {
        let lights = if self.lights_before > 0 {
            format!(
                ", {} {arrow} {} lights",
                self.lights_before, self.lights_after
            )
        } else {
            String::new()
        };
        format!(
            "{} {arrow} {} triangles, {} {arrow} {} objects{lights}, {} {arrow} {} bytes, \
             {}x{} {arrow} {}x{} pixels ({} check runs, {} candidates{})",
            self.triangles_before,
            self.triangles_after,
            self.objects_before,
            self.objects_after,
            self.bytes_before,
            self.bytes_after,
            self.image_before[0],
            self.image_before[1],
            self.image_after[0],
            self.image_after[1],
            self.check_runs,
            self.candidates,
            if self.complete {
                ""
            } else {
                "; the budget ran out"
            }
        )
    }
}

/// One distinct finding.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    /// `F1`, `F2`, ... in signature order.
    pub id: String,
    /// What groups it.
    pub signature: Signature,
    /// Generated scenes that hit it.
    pub hits: usize,
    /// Their names, in generation order.
    pub scenes: Vec<String>,
    /// How many of them each grammar family (a scene's primary one) made.
    pub families: BTreeMap<String, usize>,
    /// The example's reason.
    pub reason: String,
    /// The reduction of its smallest scene, when one ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reduced: Option<ReducedRecord>,
    /// What it is (`known.rs`): set once its situation is known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub classification: Option<super::known::Classification>,
}

/// FOLDER/findings.json.
#[derive(Debug, Clone, Serialize)]
pub struct Ledger {
    /// [`FINDINGS_FORMAT`].
    pub format: String,
    /// `--seed`.
    pub seed: u64,
    /// Scenes generated.
    pub scenes: u64,
    /// The check run, relative to FOLDER: `run`, or under `--minutes` the
    /// folder `runs` holding batch k's run in `runs/b<k>` (`mod::batch_run`).
    pub run: String,
    /// `--from`'s scene files (empty for generated scenes).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub from: Vec<String>,
    /// `--from`: the base scenes' own failing verdicts (the variants are held
    /// to them: a variant failing the same way is no finding).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub base_failures: Vec<Failure>,
    /// Every failing verdict on a generated scene.
    pub failures: Vec<Failure>,
    /// Calibration (camera) failures: not per scene, so not reduced.
    pub camera_failures: Vec<Failure>,
    /// The findings.
    pub findings: Vec<Finding>,
}

/// Failures among `verdicts` on the `generated` scenes (name to primary
/// family), and the findings they group into, in signature order.
pub fn group(
    verdicts: &[Verdict],
    generated: &BTreeMap<String, String>,
) -> (Vec<Failure>, Vec<Failure>, Vec<Finding>) {
    let mut failures = Vec::new();
    let mut camera = Vec::new();
    let mut by_sig: BTreeMap<Signature, Vec<(&Verdict, &String)>> = BTreeMap::new();
    for v in verdicts {
        let Some(class) = failure_class(v) else {
            continue;
        };
        let f = Failure {
            scene: v.scene.clone(),
            backend: v.backend.clone(),
            buffer: v.buffer.clone(),
            class: class.clone(),
            reason: crate::scene::printable(&v.reason, 300),
        };
        match generated.get(&v.scene) {
            Some(family) => {
                by_sig
                    .entry(Signature {
                        backend: v.backend.clone(),
                        buffer: v.buffer.clone(),
                        class,
                        situation: Vec::new(),
                    })
                    .or_default()
                    .push((v, family));
                failures.push(f);
            }
            None => camera.push(f),
        }
    }
    let findings = by_sig
        .into_iter()
        .enumerate()
        .map(|(i, (signature, mut vs))| {
            vs.sort_by(|a, b| a.0.scene.cmp(&b.0.scene));
            let mut families = BTreeMap::new();
            for (_, f) in &vs {
                *families.entry(f.to_string()).or_insert(0) += 1;
            }
            Finding {
                id: format!("F{}", i + 1),
                signature,
                hits: vs.len(),
                scenes: vs.iter().map(|(v, _)| v.scene.clone()).collect(),
                families,
                reason: crate::scene::printable(&vs[0].0.reason, 300),
                reduced: None,
                classification: None,
            }
        })
        .collect();
    (failures, camera, findings)
}

/// Most reductions per (backend, buffer, class) group in [`split`]: each
/// is up to `--reduce-budget`, and a group of many situations is more
/// likely one cause seen in many scenes than many causes; its scenes left
/// after these are split by their own situation, unreduced.
pub const MAX_REDUCTIONS_PER_GROUP: usize = 3;

/// A reduction as [`split`] gets it: the record, and the situation of the
/// reduced scene (of the scene itself when the reduction failed).
pub type Reduced = (ReducedRecord, Vec<String>);

/// One part of a (backend, buffer, class) group after [`split`].
#[derive(Debug, Clone)]
pub struct Part {
    /// Its situation (the signature's last part).
    pub situation: Vec<String>,
    /// Its scenes, in the group's order.
    pub scenes: Vec<String>,
    /// The reduction of its smallest scene, when one ran.
    pub reduced: Option<ReducedRecord>,
}

/// Splits a group's `scenes` (one backend, buffer and class) by situation:
/// while scenes are left, the smallest (`size`, then the first) is reduced
/// (`reduce`: the record and the situation of its reduced scene, or of the
/// scene itself when the reduction failed; None when nothing is reduced),
/// at most [`MAX_REDUCTIONS_PER_GROUP`] times, else its own situation
/// (`own`) is used; it and every scene left whose own situation holds all of
/// those tags form a part. Parts of equal situation are one part (the first
/// reduction kept).
pub fn split(
    scenes: &[String],
    own: &dyn Fn(&str) -> Vec<String>,
    size: &dyn Fn(&str) -> u64,
    reduce: &mut dyn FnMut(&str) -> Option<Reduced>,
) -> Vec<Part> {
    let mut pending: Vec<&String> = scenes.iter().collect();
    let mut parts: Vec<Part> = Vec::new();
    let mut reductions = 0;
    while let Some(&first) = pending.iter().min_by_key(|s| size(s.as_str())) {
        let (reduced, situation) = match (reductions < MAX_REDUCTIONS_PER_GROUP)
            .then(|| reduce(first.as_str()))
            .flatten()
        {
            Some((r, sit)) => {
                reductions += 1;
                (Some(r), sit)
            }
            None => (None, own(first.as_str())),
        };
        let (members, rest): (Vec<&String>, Vec<&String>) = pending.into_iter().partition(|s| {
            *s == first || {
                let tags = own(s.as_str());
                situation.iter().all(|t| tags.contains(t))
            }
        });
        pending = rest;
        let members: Vec<String> = members.into_iter().cloned().collect();
        match parts.iter_mut().find(|p| p.situation == situation) {
            Some(p) => {
                p.scenes.extend(members);
                p.scenes.sort_by_key(|s| scenes.iter().position(|x| x == s));
                if p.reduced.is_none() {
                    p.reduced = reduced;
                }
            }
            None => parts.push(Part {
                situation,
                scenes: members,
                reduced,
            }),
        }
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    fn verdict(scene: &str, buffer: &str, status: Status, counts: &[(&str, u64)]) -> Verdict {
        Verdict {
            scene: scene.into(),
            backend: "b".into(),
            buffer: buffer.into(),
            status,
            reason: "why".into(),
            counts: counts.iter().map(|(k, n)| (k.to_string(), *n)).collect(),
            errors: BTreeMap::new(),
        }
    }

    #[test]
    fn classes_follow_the_verifier_counts_and_the_buffer() {
        let c = |v: Verdict| failure_class(&v);
        assert_eq!(c(verdict("s", "id", Status::Pass, &[])), None);
        assert_eq!(c(verdict("s", "id", Status::ExpectedFail, &[])), None);
        let both = [("crack_mismatches", 2), ("interior_mismatches", 1)];
        assert_eq!(
            c(verdict("s", "id", Status::Fail, &both)).as_deref(),
            Some("interior")
        );
        let crack = [("crack_mismatches", 2), ("interior_mismatches", 0)];
        assert_eq!(
            c(verdict("s", "id", Status::Fail, &crack)).as_deref(),
            Some("crack")
        );
        assert_eq!(
            c(verdict("s", "Z", Status::Fail, &[])).as_deref(),
            Some("depth")
        );
        assert_eq!(
            c(verdict("s", "Z", Status::Error, &[])).as_deref(),
            Some("error")
        );
    }

    fn record(from: &str) -> ReducedRecord {
        ReducedRecord {
            from: from.into(),
            complete: true,
            ..ReducedRecord::default()
        }
    }

    #[test]
    fn groups_split_by_the_reduced_situation() {
        let names: Vec<String> = ["a", "b", "c", "d", "e"].map(String::from).to_vec();
        let own = |s: &str| -> Vec<String> {
            match s {
                "a" | "b" => vec!["coplanar".into(), "sliver".into()],
                "c" => vec!["coplanar".into()],
                "d" => vec!["far_from_origin".into(), "sliver".into()],
                _ => vec!["distant".into()],
            }
        };
        // b is the smallest, then d, then a, c, e.
        let size = |s: &str| -> u64 {
            match s {
                "b" => 1,
                "d" => 2,
                _ => 3,
            }
        };
        // b reduces to a coplanar pair (its sliver removed), d to a far
        // sliver; e's reduction fails (its own situation then).
        let mut reduced = Vec::new();
        let mut reduce = |s: &str| -> Option<(ReducedRecord, Vec<String>)> {
            reduced.push(s.to_string());
            let sit = match s {
                "b" => vec!["coplanar".to_string()],
                "d" => vec!["far_from_origin".into(), "sliver".into()],
                _ => own(s),
            };
            Some((record(s), sit))
        };
        let parts = split(&names, &own, &size, &mut reduce);
        assert_eq!(reduced, ["b", "d", "e"]);
        assert_eq!(parts.len(), 3);
        assert_eq!(parts[0].situation, ["coplanar"]);
        assert_eq!(parts[0].scenes, ["a", "b", "c"]);
        assert_eq!(parts[0].reduced.as_ref().unwrap().from, "b");
        assert_eq!(parts[1].scenes, ["d"]);
        assert_eq!(
            (parts[2].situation.clone(), parts[2].scenes.clone()),
            (vec!["distant".to_string()], vec!["e".to_string()])
        );

        // Nothing reduced: each part is its smallest scene's own situation.
        let parts = split(&names, &own, &size, &mut |_| None);
        let sits: Vec<&[String]> = parts.iter().map(|p| p.situation.as_slice()).collect();
        assert_eq!(sits.len(), 4, "{sits:?}");
        assert_eq!(parts[0].scenes, ["a", "b"]);
        assert!(parts.iter().all(|p| p.reduced.is_none()));

        // The cap: after MAX_REDUCTIONS_PER_GROUP reductions, own situations.
        let many: Vec<String> = (0..9).map(|i| format!("s{i}")).collect();
        let own_i = |s: &str| vec![s.to_string()];
        let mut n = 0;
        let parts = split(&many, &own_i, &|_| 0, &mut |s| {
            n += 1;
            Some((record(s), vec![s.to_string()]))
        });
        assert_eq!(parts.len(), 9);
        assert_eq!(n, MAX_REDUCTIONS_PER_GROUP);
        assert_eq!(
            parts.iter().filter(|p| p.reduced.is_some()).count(),
            MAX_REDUCTIONS_PER_GROUP
        );
    }

    #[test]
    fn failures_group_by_signature_and_probes_stay_apart() {
        let gen: BTreeMap<String, String> = [("a", "coplanar"), ("b", "coplanar"), ("c", "sliver")]
            .iter()
            .map(|(s, f)| (s.to_string(), f.to_string()))
            .collect();
        let i = [("interior_mismatches", 3)];
        let vs = vec![
            verdict("b", "id", Status::Fail, &i),
            verdict("b", "Z", Status::Fail, &[]),
            verdict("a", "id", Status::Fail, &i),
            verdict("a", "Z", Status::Pass, &[]),
            verdict("c", "id", Status::Fail, &i),
            verdict("camera_near", "camera", Status::Fail, &[]),
        ];
        let (failures, camera, findings) = group(&vs, &gen);
        assert_eq!(failures.len(), 4);
        assert_eq!(camera.len(), 1);
        // id/interior on a, b, c; Z/depth on b: two signatures ("Z" sorts first).
        assert_eq!(findings.len(), 2);
        let (z, id) = (&findings[0], &findings[1]);
        assert_eq!(
            (z.signature.buffer.as_str(), z.signature.class.as_str()),
            ("Z", "depth")
        );
        assert_eq!(z.scenes, vec!["b"]);
        assert_eq!(id.signature.class, "interior");
        assert_eq!(id.scenes, vec!["a", "b", "c"]);
        assert_eq!(id.hits, 3);
        assert_eq!(id.families["coplanar"], 2);
        assert_eq!(id.families["sliver"], 1);
        assert_eq!((z.id.as_str(), id.id.as_str()), ("F1", "F2"));
    }
}
