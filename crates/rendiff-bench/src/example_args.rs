//! The command line of the bench's examples (`cargo run --example ...`):
//! positional arguments with defaults, `--json=FILE` anywhere, comma-separated
//! counts, and a BVH quality or native Embree configuration by name. One home,
//! so the examples read and refuse their arguments alike.

use anyhow::{Context, Result};
use rendiff::names::Named;
use rendiff::trace::BvhQuality;

use crate::native_embree::Config;

/// An example's arguments: the positional ones, and where to write its JSON.
pub struct ExampleArgs {
    /// `--json=FILE` (the last one given), if any.
    pub json_out: Option<String>,
    positional: Vec<String>,
}

impl ExampleArgs {
    /// The process's arguments.
    pub fn from_env() -> Self {
        Self::new(std::env::args().skip(1))
    }

    /// These arguments (without the program name).
    pub fn new(args: impl IntoIterator<Item = String>) -> Self {
        let (json, positional): (Vec<String>, Vec<String>) =
            args.into_iter().partition(|a| a.starts_with("--json="));
        let json_out = json.last().map(|a| a["--json=".len()..].to_string());
        ExampleArgs {
            json_out,
            positional,
        }
    }

    /// The `i`-th positional argument, or `default`.
    pub fn get(&self, i: usize, default: &str) -> String {
        self.positional
            .get(i)
            .cloned()
            .unwrap_or_else(|| default.to_string())
    }

    /// The `i`-th positional argument (or `default`) as comma-separated counts.
    pub fn counts(&self, i: usize, default: &str, what: &str) -> Result<Vec<usize>> {
        self.get(i, default)
            .split(',')
            .filter(|p| !p.is_empty())
            .map(|p| {
                p.parse::<usize>()
                    .with_context(|| format!("{what}: {p:?} is not a count"))
            })
            .collect()
    }

    /// The `i`-th positional argument (or `default`) as a BVH quality.
    pub fn bvh(&self, i: usize, default: &str) -> Result<BvhQuality> {
        bvh_quality(&self.get(i, default))
    }

    /// The `i`-th positional argument (or `default`) as a native Embree
    /// configuration, by its record name.
    pub fn embree(&self, i: usize, default: &str) -> Result<Config> {
        let want = self.get(i, default);
        Config::all()
            .into_iter()
            .find(|c| c.name() == want)
            .ok_or_else(|| {
                let names: Vec<String> = Config::all().iter().map(|c| c.name()).collect();
                anyhow::anyhow!("no configuration {want:?}; one of {names:?}")
            })
    }
}

/// The BVH quality named `name`; an error lists every name.
pub fn bvh_quality(name: &str) -> Result<BvhQuality> {
    BvhQuality::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = BvhQuality::ALL.iter().map(|q| q.name()).collect();
        anyhow::anyhow!("BVH {name:?}: one of {names:?}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(a: &[&str]) -> ExampleArgs {
        ExampleArgs::new(a.iter().map(|s| s.to_string()))
    }

    #[test]
    fn json_anywhere_positional_in_order_defaults_past_the_end() {
        let a = args(&["5", "--json=a.json", "1,2", "--json=b.json"]);
        assert_eq!(a.json_out.as_deref(), Some("b.json"));
        assert_eq!(a.get(0, "x"), "5");
        assert_eq!(a.get(1, "x"), "1,2");
        assert_eq!(a.get(2, "x"), "x");
        assert_eq!(a.counts(1, "", "THREADS").unwrap(), vec![1, 2]);
        assert!(args(&[]).json_out.is_none());
    }

    #[test]
    fn bad_counts_names_and_configurations_are_refused_by_name() {
        let a = args(&["1,x", "blocky", "native nothing"]);
        assert!(format!("{:#}", a.counts(0, "", "THREADS").unwrap_err()).contains("THREADS"));
        assert!(a.bvh(1, "").unwrap_err().to_string().contains("very_fast"));
        assert!(a.embree(2, "").unwrap_err().to_string().contains("native"));
        assert_eq!(args(&[]).bvh(0, "medium").unwrap(), BvhQuality::Medium);
        let first = Config::all()[0];
        assert_eq!(
            args(&[&first.name()]).embree(0, "").unwrap().name(),
            first.name()
        );
    }
}
