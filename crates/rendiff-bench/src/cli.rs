//! The `rendiff bench` subcommands' options (clap), kept in the library so
//! that `main.rs` only names them, and their dispatch: each subcommand runs,
//! writes `OUT/<name>.json`, `OUT/<name>.html` and its SVGs, and prints where.

use super::crossover::{self, CrossoverOptions};
use super::knobs::{self, KnobsOptions, SceneSpec};
use super::peers::{self, PeersOptions};
use super::scale::{self, ScaleOptions};
use super::stability::{self, StabilityOptions};
use super::variance::{self, VarianceOptions};
use super::{Common, Output};
use anyhow::Result;
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
    /// benchmark runs; its numbers mean nothing.
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

impl CommonArgs {
    fn common(&self) -> Result<Common> {
        Ok(Common {
            runs: self.runs.unwrap_or(if self.quick { 1 } else { 3 }),
            quick: self.quick,
            out_dir: self.output.clone(),
            root: std::env::current_dir()?,
            timeout_s: self.timeout,
        })
    }
}

/// `rendiff bench knobs`'s options (boxed in [`BenchCommand`]: they outnumber the others').
#[derive(Debug, Clone, clap::Args)]
pub struct KnobsArgs {
    /// Options every subcommand takes.
    #[command(flatten)]
    pub common: CommonArgs,
    /// Visibility scenes, PATH or PATH@WxH (default: million@960x540 and pixel_grid; --quick: icosphere@64x48).
    #[arg(long = "scene")]
    pub scenes: Vec<SceneSpec>,
    /// Resolution factors of the first scene's size.
    #[arg(long, value_delimiter = ',', default_value = "0.25,0.5,1,2", value_parser = knobs::parse_scale)]
    pub scales: Vec<f64>,
    /// Global-illumination scene for the spp knobs.
    #[arg(long, default_value = "scenes/cornell_gi.toml")]
    pub gi_scene: PathBuf,
    /// Its cached reference EXR.
    #[arg(long, default_value = "tests/references/cornell_gi.exr")]
    pub reference: PathBuf,
    /// Core path tracer spp settings.
    #[arg(long, value_delimiter = ',', default_value = "1,4,16,64,256", value_parser = rendiff::args::parse_spp)]
    pub spp: Vec<u32>,
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
    /// (default: directional_shadows@320x240 and two_lights_shadowless@320x240; --quick: directional_shadows@32x24).
    #[arg(long = "direct-scene")]
    pub direct_scenes: Vec<SceneSpec>,
    /// Direct-lighting reference: K×K pixel-center samples per pixel, box-filtered (a power of two; --quick: 4).
    #[arg(long, default_value_t = 16, value_parser = parse_supersample)]
    pub supersample: u32,
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
        /// Throughput scene, PATH or PATH@WxH (--quick: icosphere@64x48).
        #[arg(long, default_value = "scenes/million.toml@1920x1080")]
        scene: SceneSpec,
        /// A real scanned mesh measured the same way, PATH or PATH@WxH
        /// (default: scenes/corpus/nefertiti_scan.toml@1920x1080; --quick: none unless given).
        #[arg(long)]
        scanned_scene: Option<SceneSpec>,
        /// Thread counts for trace and raster throughput.
        #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = rendiff::args::parse_threads)]
        threads: Vec<usize>,
        /// Global-illumination scene for the equal-time comparison.
        #[arg(long, default_value = "scenes/cornell_gi.toml")]
        gi_scene: PathBuf,
        /// Its cached reference EXR.
        #[arg(long, default_value = "tests/references/cornell_gi.exr")]
        reference: PathBuf,
        /// Mitsuba's spp at equal time (the core's spp is chosen to match its time).
        #[arg(long, default_value_t = 64, value_parser = rendiff::args::parse_spp)]
        mitsuba_spp: u32,
        /// Seed of both path tracers.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Skip external renderers (pyrender, Mitsuba).
        #[arg(long)]
        no_external: bool,
    },
    /// Raster vs trace time and operation counts as a screen-filling grid goes from 2 to millions of triangles.
    Crossover {
        /// Options every subcommand takes.
        #[command(flatten)]
        common: CommonArgs,
        /// Square image size in pixels, within the scenes' image limits (--quick: 64).
        #[arg(long, default_value_t = 512)]
        size: u32,
        /// Grid subdivisions per side (2 nx^2 triangles) (--quick: 1,4,16).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "1,2,4,8,16,32,64,128,256,512,1024,2048"
        )]
        nx: Vec<u32>,
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
        /// Shard counts to measure.
        #[arg(long, value_delimiter = ',', default_value = "1,2,4",
              value_parser = clap::value_parser!(u32).range(1..))]
        shards: Vec<u32>,
        /// Scene files or folders (default: the main job's, scenes/ and scenes/corpus/).
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
        /// Global-illumination scene.
        #[arg(long, default_value = "scenes/cornell_gi.toml")]
        scene: PathBuf,
        /// Its cached reference EXR (with var.R/G/B).
        #[arg(long, default_value = "tests/references/cornell_gi.exr")]
        reference: PathBuf,
        /// Samples per pixel settings, at least 2 each (--quick: 4,8).
        #[arg(long, value_delimiter = ',', default_value = "16,64,256", value_parser = rendiff::args::parse_spp)]
        spp: Vec<u32>,
        /// Independent seeds per setting (--quick: 8).
        #[arg(long, default_value_t = 64)]
        seeds: u64,
        /// First seed.
        #[arg(long, default_value_t = 1000)]
        seed: u64,
        /// Disjoint seed blocks on which the quick calibration test's false-alarm rate is measured (--quick: 1).
        #[arg(long, default_value_t = 64)]
        test_blocks: u64,
        /// A second, independent reference EXR of the scene (another seed), to check the
        /// reference's stated variance.
        #[arg(long)]
        check_reference: Option<PathBuf>,
        /// Worker threads (default: all CPUs).
        #[arg(long, value_parser = rendiff::args::parse_threads)]
        threads: Option<usize>,
    },
}

/// Runs one subcommand and writes its outputs.
pub fn run(cmd: BenchCommand) -> Result<()> {
    let (stem, common, out): (&str, Common, Output) = match cmd {
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
            let c = common.common()?;
            let quick = c.quick;
            if let Some(d) = mitsuba_max_depth.iter().find(|&&d| d == 0 || d < -1) {
                anyhow::bail!("--mitsuba-max-depth: {d} is neither -1 (unlimited) nor >= 1");
            }
            let direct_scenes = if !direct_scenes.is_empty() {
                direct_scenes
            } else if quick {
                vec!["scenes/directional_shadows.toml@32x24"
                    .parse()
                    .map_err(anyhow::Error::msg)?]
            } else {
                vec![
                    "scenes/directional_shadows.toml@320x240"
                        .parse()
                        .map_err(anyhow::Error::msg)?,
                    "scenes/two_lights_shadowless.toml@320x240"
                        .parse()
                        .map_err(anyhow::Error::msg)?,
                ]
            };
            let scenes = if !scenes.is_empty() {
                scenes
            } else if quick {
                vec!["scenes/icosphere.toml@64x48"
                    .parse()
                    .map_err(anyhow::Error::msg)?]
            } else {
                vec![
                    "scenes/million.toml@960x540"
                        .parse()
                        .map_err(anyhow::Error::msg)?,
                    "scenes/pixel_grid.toml"
                        .parse()
                        .map_err(anyhow::Error::msg)?,
                ]
            };
            let opts = KnobsOptions {
                common: c.clone(),
                scenes,
                resolution_scales: if quick { vec![0.5, 1.0] } else { scales },
                gi_scene,
                reference,
                core_spp: if quick { vec![1, 4] } else { spp },
                mitsuba_spp,
                mitsuba_knob_spp,
                mitsuba_max_depth,
                mitsuba_variants: mitsuba_variant,
                direct_scenes,
                supersample: if quick { 4 } else { supersample },
                seed,
                threads: threads.unwrap_or_else(super::cpus),
                no_external: no_external || quick,
            };
            ("knobs", c, knobs::run(&opts)?)
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
        } => {
            let c = common.common()?;
            let quick = c.quick;
            let opts = PeersOptions {
                common: c.clone(),
                scene: if quick {
                    "scenes/icosphere.toml@64x48"
                        .parse()
                        .map_err(anyhow::Error::msg)?
                } else {
                    scene
                },
                scanned_scene: match scanned_scene {
                    Some(s) => Some(s),
                    None if quick => None,
                    None => Some(
                        "scenes/corpus/nefertiti_scan.toml@1920x1080"
                            .parse()
                            .map_err(anyhow::Error::msg)?,
                    ),
                },
                threads: if quick { vec![1] } else { threads },
                gi_scene,
                reference,
                mitsuba_spp,
                seed,
                no_external: no_external || quick,
            };
            ("peers", c, peers::run(&opts)?)
        }
        BenchCommand::Crossover {
            common,
            size,
            nx,
            threads,
        } => {
            let c = common.common()?;
            let quick = c.quick;
            let opts = CrossoverOptions {
                common: c.clone(),
                size: if quick { 64 } else { size },
                nx: if quick { vec![1, 4, 16] } else { nx },
                threads: threads.unwrap_or_else(super::cpus),
            };
            ("crossover", c, crossover::run(&opts)?)
        }
        BenchCommand::Scale {
            common,
            shards,
            scenes,
        } => {
            let explicit_runs = common.runs.is_some();
            let mut c = common.common()?;
            if !explicit_runs {
                c.runs = 1; // each run is a whole check of minutes
            }
            let quick = c.quick;
            let scenes = if quick {
                vec![
                    c.root.join("scenes/three_triangles.toml"),
                    c.root.join("scenes/icosphere.toml"),
                ]
            } else if scenes.is_empty() {
                vec![c.root.join("scenes"), c.root.join("scenes/corpus")]
            } else {
                scenes
            };
            let opts = ScaleOptions {
                common: c.clone(),
                shards: if quick { vec![2] } else { shards },
                scenes,
            };
            ("scale", c, scale::run(&opts)?)
        }
        BenchCommand::Stability { common, only } => {
            let c = common.common()?;
            let opts = StabilityOptions {
                common: c.clone(),
                only,
            };
            ("stability", c, stability::run(&opts)?)
        }
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
            let c = common.common()?;
            let quick = c.quick;
            let opts = VarianceOptions {
                common: c.clone(),
                scene,
                reference,
                spp: if quick { vec![4, 8] } else { spp },
                seeds: if quick { 8 } else { seeds },
                seed,
                test_blocks: if quick { 1 } else { test_blocks },
                check_reference,
                threads: threads.unwrap_or_else(super::cpus),
            };
            ("variance", c, variance::run(&opts)?)
        }
    };
    let written = super::write_outputs(&common.out_dir, stem, &out.record, &out.html, &out.svgs)?;
    for p in written {
        println!("wrote {}", p.display());
    }
    Ok(())
}
