//! The `rendiff bench` subcommands' options (clap), kept in the library so
//! that `main.rs` only names them, and their dispatch: each subcommand runs,
//! writes `OUT/<name>.json`, `OUT/<name>.html` and its SVGs as one set, and
//! prints where.
//!
//! Two rules hold for every subcommand. `--quick` only changes the defaults
//! of options not given: an option given explicitly is used as given, with
//! or without `--quick` ([`plan`] resolves both). And rendiff's own files
//! named by a default (scenes, references) are found in rendiff's checkout
//! the way `rendiff check` finds it (`RENDIFF_HOME`, the current folder if
//! it is a checkout, else the checkout the binary was built from:
//! [`rendiff::check::find_root`]), so a benchmark works from any folder;
//! paths given on the command line are relative to the current folder, and
//! so is the default output folder.

use super::crossover::{self, CrossoverOptions};
use super::fuzz::{self, FuzzBenchOptions};
use super::knobs::{self, KnobsOptions, SceneSpec};
use super::peers::{self, PeersOptions};
use super::scale::{self, ScaleOptions};
use super::stability::{self, StabilityOptions};
use super::variance::{self, VarianceOptions};
use super::{Common, Output};
use anyhow::{Context, Result};
use std::path::PathBuf;

/// `--supersample K` ([`super::direct::check_supersample`]).
fn parse_supersample(s: &str) -> std::result::Result<u32, String> {
    let k: u32 = s.parse().map_err(|_| format!("{s:?} is not a count"))?;
    super::direct::check_supersample(k).map(|()| k)
}

/// Options every subcommand takes.
#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Tiny configuration (small images, one run, no external renderers): checks the
    /// benchmark runs; its numbers mean nothing. It changes only the defaults of options
    /// not given ("--quick: ..." in their help): an option given explicitly is used as given.
    #[arg(long)]
    pub quick: bool,
    /// Timed runs per configuration, after one warm-up (default 3; 1 with --quick).
    #[arg(long, value_parser = rendiff::args::parse_runs)]
    pub runs: Option<usize>,
    /// Output folder for JSON, HTML and SVG.
    #[arg(short, long, default_value = "reports/bench")]
    pub output: PathBuf,
    /// Seconds before an external renderer is killed (1 to a week).
    #[arg(long, default_value_t = 600, value_parser = rendiff::args::parse_timeout)]
    pub timeout: u64,
}

/// The path-traced scene the radiance benchmarks default to, and its cached
/// Mitsuba reference.
const GI_SCENE: &str = "scenes/cornell_gi.toml";
const GI_REFERENCE: &str = "tests/references/cornell_gi.exr";

/// rendiff's checkout, where the defaults' files live ([`rendiff::check::find_root`]),
/// or why it was not found (an error only once a default needs it).
#[derive(Debug, Clone)]
pub struct Home(std::result::Result<PathBuf, String>);

impl Home {
    /// Finds the checkout as `rendiff check` does.
    pub fn find() -> Home {
        Home(rendiff::check::find_root().map_err(|e| format!("{e:#}")))
    }

    /// `rel`, one of rendiff's own files, in the checkout (relative as given
    /// when the checkout is the current folder: [`rendiff::check::in_root`]).
    pub fn file(&self, rel: &str) -> Result<PathBuf> {
        match &self.0 {
            Ok(root) => Ok(rendiff::check::in_root(root, rel)),
            Err(e) => anyhow::bail!("{rel} (a default): {e}"),
        }
    }

    /// `given` when the user gave it, else the default file `rel` in the checkout.
    pub fn or_file(&self, given: Option<PathBuf>, rel: &str) -> Result<PathBuf> {
        given.map_or_else(|| self.file(rel), Ok)
    }

    /// A default `PATH[@WxH]`, its path in the checkout.
    pub fn spec(&self, spec: &str) -> Result<SceneSpec> {
        let mut s: SceneSpec = spec.parse().map_err(anyhow::Error::msg)?;
        s.path = self.file(&s.path.to_string_lossy())?;
        Ok(s)
    }

    /// The checkout, or the current folder where none was found (the
    /// harness and its venv are looked for there, and reported missing).
    fn root(&self) -> Result<PathBuf> {
        match &self.0 {
            Ok(r) => Ok(r.clone()),
            Err(_) => std::env::current_dir().context("cannot read the current folder"),
        }
    }
}

impl CommonArgs {
    fn common(&self, home: &Home) -> Result<Common> {
        Ok(Common {
            runs: self.runs.unwrap_or(if self.quick { 1 } else { 3 }),
            quick: self.quick,
            out_dir: self.output.clone(),
            root: home.root()?,
            timeout_s: self.timeout,
        })
    }
}

/// `given` if the option was given, else `--quick`'s default or the normal one.
fn pick<T>(given: Option<T>, quick: bool, quick_default: T, default: T) -> T {
    given.unwrap_or(if quick { quick_default } else { default })
}

/// `rendiff bench knobs`'s options (boxed in [`BenchCommand`]: they outnumber the others').
#[derive(Debug, Clone, clap::Args)]
pub struct KnobsArgs {
    /// Options every subcommand takes.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Visibility scenes, PATH or PATH@WxH (default: scenes/million.toml@960x540 and
    /// scenes/pixel_grid.toml; --quick: scenes/icosphere.toml@64x48).
    #[arg(long = "scene")]
    pub scenes: Vec<SceneSpec>,
    /// Resolution factors of the first scene's size (default: 0.25,0.5,1,2; --quick: 0.5,1).
    #[arg(long, value_delimiter = ',', value_parser = knobs::parse_scale)]
    pub scales: Option<Vec<f64>>,
    /// Global-illumination scene for the spp knobs (default: scenes/cornell_gi.toml).
    #[arg(long)]
    pub gi_scene: Option<PathBuf>,
    /// Its cached reference EXR (default: tests/references/cornell_gi.exr).
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Core path tracer spp settings (default: 1,4,16,64,256; --quick: 1,4).
    #[arg(long, value_delimiter = ',', value_parser = rendiff::args::parse_spp)]
    pub spp: Option<Vec<u32>>,
    /// Mitsuba spp settings (at least 2 each).
    #[arg(long, value_delimiter = ',', default_value = "4,16,64,256", value_parser = rendiff::args::parse_spp)]
    pub mitsuba_spp: Vec<u32>,
    /// Mitsuba's spp for its max_depth and variant knobs.
    #[arg(long, default_value_t = 64, value_parser = rendiff::args::parse_spp)]
    pub mitsuba_knob_spp: u32,
    /// Mitsuba max_depth settings (-1 = unlimited, or >= 1; the reference uses -1).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "2,3,5",
        allow_hyphen_values = true
    )]
    pub mitsuba_max_depth: Vec<i32>,
    /// Mitsuba variants beside the default scalar_rgb (llvm_ad_rgb needs libLLVM 19: DRJIT_LIBLLVM_PATH, else Debian's libllvm19).
    #[arg(long, value_delimiter = ',', default_value = "llvm_ad_rgb",
          value_parser = ["scalar_rgb", "llvm_ad_rgb"])]
    pub mitsuba_variant: Vec<String>,
    /// Locally shaded scenes for the direct-lighting knobs (POV-Ray antialiasing and quality, pyrender, core supersampling), PATH or PATH@WxH
    /// (default: scenes/directional_shadows.toml@320x240 and scenes/two_lights_shadowless.toml@320x240;
    /// --quick: scenes/directional_shadows.toml@32x24).
    #[arg(long = "direct-scene")]
    pub direct_scenes: Vec<SceneSpec>,
    /// Direct-lighting reference: K×K pixel-center samples per pixel, box-filtered
    /// (a power of two; default: 16; --quick: 4).
    #[arg(long, value_parser = parse_supersample)]
    pub supersample: Option<u32>,
    /// Seed of both path tracers (the reference used 0, so not 0).
    #[arg(long, default_value_t = 1000)]
    pub seed: u64,
    /// Worker threads (default: all CPUs).
    #[arg(long, value_parser = rendiff::args::parse_threads)]
    pub threads: Option<usize>,
    /// Skip external renderers (POV-Ray, pyrender, Mitsuba).
    #[arg(long)]
    pub no_external: bool,
}

/// `rendiff bench <what>`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum BenchCommand {
    /// Every speed/accuracy knob against one reference: time-vs-error table and plot with the Pareto front.
    Knobs(Box<KnobsArgs>),
    /// The core next to Embree, pyrender and Mitsuba on identical work, as ratios.
    Peers {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Throughput scene, PATH or PATH@WxH (default: scenes/million.toml@1920x1080;
        /// --quick: scenes/icosphere.toml@64x48).
        #[arg(long)]
        scene: Option<SceneSpec>,
        /// A real scanned mesh measured the same way, PATH or PATH@WxH
        /// (default: scenes/corpus/nefertiti_scan.toml@1920x1080; --quick: none unless given).
        #[arg(long)]
        scanned_scene: Option<SceneSpec>,
        /// Thread counts for trace and raster throughput (default: 1,2; --quick: 1).
        #[arg(long, value_delimiter = ',', value_parser = rendiff::args::parse_threads)]
        threads: Option<Vec<usize>>,
        /// Global-illumination scene for the equal-time comparison (default: scenes/cornell_gi.toml).
        #[arg(long)]
        gi_scene: Option<PathBuf>,
        /// Its cached reference EXR (default: tests/references/cornell_gi.exr).
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Mitsuba's spp at equal time (the core's spp is chosen to match its time).
        #[arg(long, default_value_t = 64, value_parser = rendiff::args::parse_spp)]
        mitsuba_spp: u32,
        /// Seed of both path tracers.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Skip external renderers (pyrender, Mitsuba).
        #[arg(long)]
        no_external: bool,
        /// Paired rounds, in alternating order, behind each core-vs-Embree
        /// ratio and the check of Embree against the native driver (default: 11; --quick: 3).
        #[arg(long, value_parser = rendiff::args::parse_runs)]
        rounds: Option<usize>,
    },
    /// Raster vs trace time and operation counts as a screen-filling grid goes from 2 to millions of triangles.
    Crossover {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Square image size in pixels, within the scenes' image limits (default: 512; --quick: 64).
        #[arg(long)]
        size: Option<u32>,
        /// Grid subdivisions per side, 2 nx^2 triangles
        /// (default: 1,2,4,8,16,32,64,128,256,512,1024,2048; --quick: 1,4,16).
        #[arg(long, value_delimiter = ',')]
        nx: Option<Vec<u32>>,
        /// Worker threads (default: all CPUs).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        threads: Option<usize>,
    },
    /// The main job's wall time: a process per render one at a time, the
    /// default (workers and the job pool), and N shards then merged
    /// (`scale.json`; one run of each whole check unless --runs).
    Scale {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Shard counts to measure (default: 1,2,4; --quick: 2).
        #[arg(long, value_delimiter = ',',
              value_parser = clap::value_parser!(u32).range(1..))]
        shards: Option<Vec<u32>>,
        /// Scene files or folders (default: the main job's, scenes/ and scenes/corpus/;
        /// --quick: scenes/three_triangles.toml and scenes/icosphere.toml).
        #[arg(long = "scene")]
        scenes: Vec<PathBuf>,
    },
    /// Scene families at numerical extremes through `rendiff check`: where each renderer breaks, and how.
    Stability {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Only these backends, comma-separated (--quick: raster,trace,embree,embree_robust).
        #[arg(long, value_delimiter = ',')]
        only: Option<Vec<String>>,
    },
    /// Whether the core path tracer's variance-of-the-mean estimate is calibrated (many seeds), and its bias vs the reference.
    Variance {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Global-illumination scene (default: scenes/cornell_gi.toml).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Its cached reference EXR, with var.R/G/B (default: tests/references/cornell_gi.exr).
        #[arg(long)]
        reference: Option<PathBuf>,
        /// Samples per pixel settings, at least 2 each (default: 16,64,256; --quick: 4,8).
        #[arg(long, value_delimiter = ',', value_parser = rendiff::args::parse_spp)]
        spp: Option<Vec<u32>>,
        /// Independent seeds per setting (default: 64; --quick: 8).
        #[arg(long)]
        seeds: Option<u64>,
        /// First seed.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Disjoint seed blocks on which the quick calibration test's false-alarm rate is
        /// measured (default: 64; --quick: 1).
        #[arg(long)]
        test_blocks: Option<u64>,
        /// A second, independent reference EXR of the scene (another seed), to check the
        /// reference's stated variance.
        #[arg(long)]
        check_reference: Option<PathBuf>,
        /// Worker threads (default: all CPUs).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        threads: Option<usize>,
    },
    /// Generated scenes a minute through `rendiff fuzz`, all backends together and each
    /// alone, each renderer's start-up share, and reduction time per finding.
    Fuzz {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// The generator's seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Scenes per timed fuzz run (default: 50, one `--minutes` batch; --quick: 4).
        #[arg(long, value_parser = clap::value_parser!(u64).range(1..=10_000))]
        count: Option<u64>,
        /// Only these backends, comma-separated (default: every one; --quick: trace).
        #[arg(long, value_delimiter = ',')]
        only: Option<Vec<String>>,
        /// External renders at a time in each fuzz run (default: the cores).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        jobs: Option<usize>,
        /// Planted renderers whose findings are reduced and timed, comma-separated
        /// (default: coplanar_bias; --quick: none), declared in --planted-renderers.
        #[arg(long, value_delimiter = ',')]
        planted: Option<Vec<String>>,
        /// Their declarations (default: tests/fuzz_renderers/renderers.toml).
        #[arg(long)]
        planted_renderers: Option<PathBuf>,
        /// Scenes fuzzed through each planted renderer (default: 50).
        #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(1..=10_000))]
        planted_count: u64,
        /// Findings reduced per planted renderer, at most.
        #[arg(long, default_value_t = 3)]
        reductions: usize,
        /// Each reduction's time budget, seconds.
        #[arg(long, default_value_t = 180, value_parser = rendiff::args::parse_timeout)]
        reduce_budget: u64,
    },
}

/// A subcommand with every option resolved: what runs.
#[derive(Debug, Clone)]
pub enum Plan {
    /// `bench knobs`.
    Knobs(Box<KnobsOptions>),
    /// `bench peers`.
    Peers(Box<PeersOptions>),
    /// `bench crossover`.
    Crossover(CrossoverOptions),
    /// `bench scale`.
    Scale(ScaleOptions),
    /// `bench stability`.
    Stability(StabilityOptions),
    /// `bench variance`.
    Variance(VarianceOptions),
    /// `bench fuzz`.
    Fuzz(Box<FuzzBenchOptions>),
}

impl Plan {
    /// The benchmark's name: its outputs are `STEM.json`, `STEM.html`, `STEM-*.svg`.
    pub fn stem(&self) -> &'static str {
        match self {
            Plan::Knobs(_) => "knobs",
            Plan::Peers(_) => "peers",
            Plan::Crossover(_) => "crossover",
            Plan::Scale(_) => "scale",
            Plan::Stability(_) => "stability",
            Plan::Variance(_) => "variance",
            Plan::Fuzz(_) => "fuzz",
        }
    }

    /// The options every subcommand shares.
    pub fn common(&self) -> &Common {
        match self {
            Plan::Knobs(o) => &o.common,
            Plan::Peers(o) => &o.common,
            Plan::Crossover(o) => &o.common,
            Plan::Scale(o) => &o.common,
            Plan::Stability(o) => &o.common,
            Plan::Variance(o) => &o.common,
            Plan::Fuzz(o) => &o.common,
        }
    }

    fn run(&self) -> Result<Output> {
        match self {
            Plan::Knobs(o) => knobs::run(o),
            Plan::Peers(o) => peers::run(o),
            Plan::Crossover(o) => crossover::run(o),
            Plan::Scale(o) => scale::run(o),
            Plan::Stability(o) => stability::run(o),
            Plan::Variance(o) => variance::run(o),
            Plan::Fuzz(o) => fuzz::run(o),
        }
    }
}

/// Resolves a subcommand's options: explicit ones as given, the others
/// `--quick`'s default or the normal one, rendiff's own files in its checkout.
pub fn plan(cmd: BenchCommand) -> Result<Plan> {
    plan_in(cmd, &Home::find())
}

/// [`plan`] with the checkout given.
pub fn plan_in(cmd: BenchCommand, home: &Home) -> Result<Plan> {
    Ok(match cmd {
        BenchCommand::Knobs(args) => {
            let KnobsArgs {
                common,
                scenes,
                scales,
                gi_scene,
                reference,
                spp,
                mitsuba_spp,
                mitsuba_knob_spp,
                mitsuba_max_depth,
                mitsuba_variant,
                direct_scenes,
                supersample,
                seed,
                threads,
                no_external,
            } = *args;
            let c = common.common(home)?;
            let quick = c.quick;
            if let Some(d) = mitsuba_max_depth.iter().find(|&&d| d == 0 || d < -1) {
                anyhow::bail!("--mitsuba-max-depth: {d} is neither -1 (unlimited) nor >= 1");
            }
            let direct_scenes = if !direct_scenes.is_empty() {
                direct_scenes
            } else if quick {
                vec![home.spec("scenes/directional_shadows.toml@32x24")?]
            } else {
                vec![
                    home.spec("scenes/directional_shadows.toml@320x240")?,
                    home.spec("scenes/two_lights_shadowless.toml@320x240")?,
                ]
            };
            let scenes = if !scenes.is_empty() {
                scenes
            } else if quick {
                vec![home.spec("scenes/icosphere.toml@64x48")?]
            } else {
                vec![
                    home.spec("scenes/million.toml@960x540")?,
                    home.spec("scenes/pixel_grid.toml")?,
                ]
            };
            Plan::Knobs(Box::new(KnobsOptions {
                common: c,
                scenes,
                resolution_scales: pick(scales, quick, vec![0.5, 1.0], vec![0.25, 0.5, 1.0, 2.0]),
                gi_scene: home.or_file(gi_scene, GI_SCENE)?,
                reference: home.or_file(reference, GI_REFERENCE)?,
                core_spp: pick(spp, quick, vec![1, 4], vec![1, 4, 16, 64, 256]),
                mitsuba_spp,
                mitsuba_knob_spp,
                mitsuba_max_depth,
                mitsuba_variants: mitsuba_variant,
                direct_scenes,
                supersample: pick(supersample, quick, 4, 16),
                seed,
                threads: threads.unwrap_or_else(super::cpus),
                no_external: no_external || quick,
            }))
        }
        BenchCommand::Peers {
            common,
            scene,
            scanned_scene,
            threads,
            gi_scene,
            reference,
            mitsuba_spp,
            seed,
            no_external,
            rounds,
        } => {
            let c = common.common(home)?;
            let quick = c.quick;
            Plan::Peers(Box::new(PeersOptions {
                common: c,
                scene: match scene {
                    Some(s) => s,
                    None if quick => home.spec("scenes/icosphere.toml@64x48")?,
                    None => home.spec("scenes/million.toml@1920x1080")?,
                },
                scanned_scene: match scanned_scene {
                    Some(s) => Some(s),
                    None if quick => None,
                    None => Some(home.spec("scenes/corpus/nefertiti_scan.toml@1920x1080")?),
                },
                threads: pick(threads, quick, vec![1], vec![1, 2]),
                gi_scene: home.or_file(gi_scene, GI_SCENE)?,
                reference: home.or_file(reference, GI_REFERENCE)?,
                mitsuba_spp,
                seed,
                no_external: no_external || quick,
                rounds: pick(rounds, quick, 3, 11),
            }))
        }
        BenchCommand::Crossover {
            common,
            size,
            nx,
            threads,
        } => {
            let c = common.common(home)?;
            let quick = c.quick;
            Plan::Crossover(CrossoverOptions {
                common: c,
                size: pick(size, quick, 64, 512),
                nx: pick(
                    nx,
                    quick,
                    vec![1, 4, 16],
                    vec![1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048],
                ),
                threads: threads.unwrap_or_else(super::cpus),
                // The default corpus is rendiff's own scenes, listed when the
                // bench runs; without a checkout the grid still runs and the
                // record says why the corpus table did not.
                corpus: if quick {
                    home.file("scenes/three_triangles.toml").map(|f| vec![f])
                } else {
                    home.file("scenes")
                        .and_then(|s| Ok(vec![s, home.file("scenes/corpus")?]))
                }
                .map_err(|e| format!("{e:#}")),
            })
        }
        BenchCommand::Scale {
            common,
            shards,
            scenes,
        } => {
            let explicit_runs = common.runs.is_some();
            let mut c = common.common(home)?;
            if !explicit_runs {
                c.runs = 1; // each run is a whole check of minutes
            }
            let quick = c.quick;
            let scenes = if !scenes.is_empty() {
                scenes
            } else if quick {
                vec![
                    home.file("scenes/three_triangles.toml")?,
                    home.file("scenes/icosphere.toml")?,
                ]
            } else {
                vec![home.file("scenes")?, home.file("scenes/corpus")?]
            };
            Plan::Scale(ScaleOptions {
                common: c,
                shards: pick(shards, quick, vec![2], vec![1, 2, 4]),
                scenes,
            })
        }
        BenchCommand::Stability { common, only } => Plan::Stability(StabilityOptions {
            common: common.common(home)?,
            only,
        }),
        BenchCommand::Variance {
            common,
            scene,
            reference,
            spp,
            seeds,
            seed,
            test_blocks,
            check_reference,
            threads,
        } => {
            let c = common.common(home)?;
            let quick = c.quick;
            Plan::Variance(VarianceOptions {
                common: c,
                scene: home.or_file(scene, GI_SCENE)?,
                reference: home.or_file(reference, GI_REFERENCE)?,
                spp: pick(spp, quick, vec![4, 8], vec![16, 64, 256]),
                seeds: pick(seeds, quick, 8, 64),
                seed,
                test_blocks: pick(test_blocks, quick, 1, 64),
                check_reference,
                threads: threads.unwrap_or_else(super::cpus),
            })
        }
        BenchCommand::Fuzz {
            common,
            seed,
            count,
            only,
            jobs,
            planted,
            planted_renderers,
            planted_count,
            reductions,
            reduce_budget,
        } => {
            let c = common.common(home)?;
            let quick = c.quick;
            let planted = pick(planted, quick, Vec::new(), vec!["coplanar_bias".into()]);
            Plan::Fuzz(Box::new(FuzzBenchOptions {
                common: c,
                seed,
                count: pick(count, quick, 4, rendiff::fuzz::BATCH),
                only: match only {
                    Some(o) => Some(o),
                    None if quick => Some(vec!["trace".into()]),
                    None => None,
                },
                jobs: jobs.unwrap_or_else(super::cpus),
                // Found in the checkout only when a planted renderer is asked for.
                planted_renderers: if planted.is_empty() {
                    planted_renderers.unwrap_or_default()
                } else {
                    home.or_file(planted_renderers, fuzz::PLANTED_RENDERERS)?
                },
                planted,
                planted_count,
                reductions,
                reduce_budget_s: reduce_budget,
            }))
        }
    })
}

/// Runs one subcommand and writes its outputs: every output path is checked
/// before the benchmark starts, and the set is written all or nothing.
pub fn run(cmd: BenchCommand) -> Result<()> {
    let plan = plan(cmd)?;
    let (stem, out_dir) = (plan.stem(), plan.common().out_dir.clone());
    super::outputs::check_targets(&out_dir, stem)?;
    let out = plan.run()?;
    let written = super::write_outputs(&out_dir, stem, &out.record, &out.html, &out.svgs)?;
    for p in written {
        rendiff::outln!("wrote {}", p.display());
    }
    Ok(())
}

/// The default scene of the plain `rendiff bench` (no subcommand), in rendiff's checkout.
pub fn default_core_scene() -> Result<PathBuf> {
    Home::find().file("scenes/million.toml")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use std::path::Path;

    #[derive(Debug, Parser)]
    struct T {
        #[command(subcommand)]
        cmd: BenchCommand,
    }

    fn plan_of(args: &[&str]) -> Plan {
        let t = T::try_parse_from(std::iter::once("bench").chain(args.iter().copied()))
            .unwrap_or_else(|e| panic!("{args:?}: {e}"));
        plan_in(t.cmd, &Home(Ok(PathBuf::from("/home/rd")))).unwrap()
    }

    fn spec(s: &str) -> SceneSpec {
        s.parse().unwrap()
    }

    /// Every option --quick has a default for is honoured when given with
    /// it (each was silently replaced by --quick's value).
    #[test]
    fn explicit_options_win_over_quick() {
        let Plan::Crossover(o) = plan_of(&["crossover", "--quick", "--nx", "1", "--size", "16"])
        else {
            panic!()
        };
        assert_eq!((o.size, o.nx, o.common.runs), (16, vec![1], 1));

        let Plan::Scale(o) = plan_of(&[
            "scale", "--quick", "--scene", "x.toml", "--shards", "3", "--runs", "2",
        ]) else {
            panic!()
        };
        assert_eq!(o.scenes, [PathBuf::from("x.toml")]);
        assert_eq!((o.shards, o.common.runs), (vec![3], 2));

        let Plan::Peers(o) = plan_of(&[
            "peers",
            "--quick",
            "--scene",
            "a.toml@8x8",
            "--threads",
            "2",
        ]) else {
            panic!()
        };
        assert_eq!((o.scene, o.threads), (spec("a.toml@8x8"), vec![2]));

        let Plan::Variance(o) = plan_of(&[
            "variance",
            "--quick",
            "--spp",
            "2",
            "--seeds",
            "3",
            "--test-blocks",
            "5",
        ]) else {
            panic!()
        };
        assert_eq!((o.spp, o.seeds, o.test_blocks), (vec![2], 3, 5));

        let Plan::Knobs(o) = plan_of(&[
            "knobs",
            "--quick",
            "--scales",
            "1",
            "--spp",
            "2",
            "--supersample",
            "2",
            "--scene",
            "a.toml",
            "--direct-scene",
            "b.toml",
        ]) else {
            panic!()
        };
        assert_eq!(o.resolution_scales, [1.0]);
        assert_eq!((o.core_spp, o.supersample), (vec![2], 2));
        assert_eq!(
            (o.scenes, o.direct_scenes),
            (vec![spec("a.toml")], vec![spec("b.toml")])
        );

        let Plan::Stability(o) = plan_of(&["stability", "--quick", "--only", "trace"]) else {
            panic!()
        };
        assert_eq!(o.only, Some(vec!["trace".to_string()]));
    }

    /// Without the options, --quick's defaults and the normal ones apply.
    #[test]
    fn quick_and_normal_defaults() {
        let Plan::Crossover(o) = plan_of(&["crossover", "--quick"]) else {
            panic!()
        };
        assert_eq!((o.size, o.nx), (64, vec![1, 4, 16]));
        let Plan::Crossover(o) = plan_of(&["crossover"]) else {
            panic!()
        };
        assert_eq!((o.size, o.nx.len(), o.common.runs), (512, 12, 3));
        let Plan::Variance(o) = plan_of(&["variance", "--quick"]) else {
            panic!()
        };
        assert_eq!((o.spp, o.seeds, o.test_blocks), (vec![4, 8], 8, 1));
        let Plan::Knobs(o) = plan_of(&["knobs"]) else {
            panic!()
        };
        assert_eq!((o.core_spp.len(), o.supersample), (5, 16));
        assert_eq!(o.resolution_scales, [0.25, 0.5, 1.0, 2.0]);
        let Plan::Scale(o) = plan_of(&["scale", "--quick"]) else {
            panic!()
        };
        assert_eq!((o.shards, o.common.runs), (vec![2], 1));
    }

    /// `bench fuzz`: --quick runs a few scenes through the tracer and reduces
    /// nothing; the normal run is one `--minutes` batch through every backend
    /// and reduces coplanar_bias's findings, declared in the checkout;
    /// explicit options win.
    #[test]
    fn fuzz_plans() {
        let Plan::Fuzz(o) = plan_of(&["fuzz", "--quick"]) else {
            panic!()
        };
        assert_eq!((o.count, o.common.runs), (4, 1));
        assert_eq!(o.only, Some(vec!["trace".to_string()]));
        assert!(o.planted.is_empty());
        let Plan::Fuzz(o) = plan_of(&["fuzz"]) else {
            panic!()
        };
        assert_eq!((o.count, o.common.runs, o.only), (50, 3, None));
        assert_eq!(o.planted, ["coplanar_bias"]);
        assert_eq!(
            o.planted_renderers,
            Path::new("/home/rd/tests/fuzz_renderers/renderers.toml")
        );
        assert_eq!(
            (o.planted_count, o.reductions, o.reduce_budget_s),
            (50, 3, 180)
        );
        let Plan::Fuzz(o) = plan_of(&[
            "fuzz",
            "--quick",
            "--count",
            "7",
            "--only",
            "povray,embree",
            "--planted",
            "far_depth",
            "--jobs",
            "2",
        ]) else {
            panic!()
        };
        assert_eq!((o.count, o.jobs), (7, 2));
        assert_eq!(o.only, Some(vec!["povray".to_string(), "embree".into()]));
        assert_eq!(o.planted, ["far_depth"]);
        assert_eq!(plan_of(&["fuzz", "--quick"]).stem(), "fuzz");
        // No checkout: --quick needs none (no planted renderers to find).
        let none = Home(Err("cannot find rendiff's harness".into()));
        let t = T::try_parse_from(["bench", "fuzz", "--quick"]).unwrap();
        assert!(plan_in(t.cmd, &none).is_ok());
        let t = T::try_parse_from(["bench", "fuzz"]).unwrap();
        assert!(plan_in(t.cmd, &none).is_err());
    }

    /// Defaults name rendiff's own files in its checkout, wherever the
    /// command runs; explicit paths stay as given (relative to the current folder).
    #[test]
    fn default_files_come_from_the_checkout() {
        let Plan::Knobs(o) = plan_of(&["knobs", "--quick"]) else {
            panic!()
        };
        assert_eq!(
            o.scenes,
            [spec("/home/rd/scenes/icosphere.toml@64x48")],
            "{o:?}"
        );
        assert_eq!(
            o.direct_scenes,
            [spec("/home/rd/scenes/directional_shadows.toml@32x24")]
        );
        assert_eq!(o.gi_scene, Path::new("/home/rd/scenes/cornell_gi.toml"));
        assert_eq!(
            o.reference,
            Path::new("/home/rd/tests/references/cornell_gi.exr")
        );
        assert_eq!(o.common.root, Path::new("/home/rd"));
        assert_eq!(o.common.out_dir, Path::new("reports/bench"));
        let Plan::Peers(o) = plan_of(&["peers"]) else {
            panic!()
        };
        assert_eq!(o.scene, spec("/home/rd/scenes/million.toml@1920x1080"));
        assert_eq!(
            o.scanned_scene,
            Some(spec("/home/rd/scenes/corpus/nefertiti_scan.toml@1920x1080"))
        );
        let Plan::Variance(o) = plan_of(&["variance", "--reference", "r.exr"]) else {
            panic!()
        };
        assert_eq!(o.scene, Path::new("/home/rd/scenes/cornell_gi.toml"));
        assert_eq!(o.reference, Path::new("r.exr"));
        let Plan::Scale(o) = plan_of(&["scale"]) else {
            panic!()
        };
        assert_eq!(
            o.scenes,
            [
                PathBuf::from("/home/rd/scenes"),
                PathBuf::from("/home/rd/scenes/corpus")
            ]
        );
        // No checkout: a default that needs one says so; explicit paths need none.
        let none = Home(Err("cannot find rendiff's harness".into()));
        let t = T::try_parse_from(["bench", "variance"]).unwrap();
        let e = plan_in(t.cmd, &none).unwrap_err();
        assert!(
            format!("{e}").contains("cannot find rendiff's harness"),
            "{e}"
        );
        let t = T::try_parse_from(["bench", "crossover"]).unwrap();
        assert!(plan_in(t.cmd, &none).is_ok());
    }
}
