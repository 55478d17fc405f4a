//! Who used the machine's CPUs while a benchmark ran: the benchmark itself,
//! other processes, or the hypervisor (steal).
//!
//! The load average alone cannot say whether a run was quiet. It counts this
//! benchmark's own threads, it lags by minutes, and on a virtual machine it
//! does not see a neighbour guest taking the physical core. The kernel's
//! per-state CPU counters (`/proc/stat`) do: their change over the run,
//! less this process's and its children's own CPU time (`getrusage`), is the
//! time other processes ran, and the `steal` column is the time the
//! hypervisor ran someone else while this machine wanted the CPU. A run
//! whose record shows both near zero ran on a quiet machine; one that shows
//! them large says by how much its numbers were disturbed.

use serde_json::{json, Value};

/// The columns of `/proc/stat`'s aggregate `cpu` line that partition time
/// (user, nice, system, idle, iowait, irq, softirq, steal). `guest` and
/// `guest_nice` follow them but are already counted in `user` and `nice`.
const COLUMNS: usize = 8;
const USER: usize = 0;
const NICE: usize = 1;
const SYSTEM: usize = 2;
const IDLE: usize = 3;
const IOWAIT: usize = 4;
const IRQ: usize = 5;
const SOFTIRQ: usize = 6;
const STEAL: usize = 7;

/// One reading of the machine's CPU-time counters and this process's own CPU
/// time, taken at the start of a run and again at its end.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CpuCounters {
    /// The machine's ticks per state, summed over its CPUs.
    pub ticks: [u64; COLUMNS],
    /// Ticks per second of `ticks` (the kernel's USER_HZ).
    pub ticks_per_s: f64,
    /// User plus system CPU seconds of this process and its waited-for children.
    pub own_s: f64,
}

/// The aggregate `cpu` line's first eight columns, or None when the text has
/// no such line or it is malformed.
pub fn parse_stat(text: &str) -> Option<[u64; COLUMNS]> {
    let line = text
        .lines()
        .find(|l| l.split_whitespace().next() == Some("cpu"))?;
    let mut it = line.split_whitespace().skip(1);
    let mut ticks = [0u64; COLUMNS];
    for t in &mut ticks {
        *t = it.next()?.parse().ok()?;
    }
    Some(ticks)
}

/// Reads the counters now, or None where the platform has no `/proc/stat`.
pub fn read() -> Option<CpuCounters> {
    let ticks = parse_stat(&std::fs::read_to_string("/proc/stat").ok()?)?;
    // SAFETY: sysconf takes no pointers; a non-positive answer is refused below.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if hz <= 0 {
        return None;
    }
    Some(CpuCounters {
        ticks,
        ticks_per_s: hz as f64,
        own_s: own_cpu_seconds()?,
    })
}

/// User plus system CPU time of this process and of the children it has waited for.
fn own_cpu_seconds() -> Option<f64> {
    let mut total = 0.0;
    for who in [libc::RUSAGE_SELF, libc::RUSAGE_CHILDREN] {
        // SAFETY: a zeroed rusage is a valid plain C struct (integers only).
        let mut u: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: getrusage writes one rusage into `u`, which we own.
        if unsafe { libc::getrusage(who, &mut u) } != 0 {
            return None;
        }
        let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        total += secs(u.ru_utime) + secs(u.ru_stime);
    }
    Some(total)
}

/// How the machine's CPU time between two readings divides among this
/// benchmark, other processes, the hypervisor and idleness, as fractions of
/// the whole (CPUs × wall time), with a one-line summary for the page; a
/// run within one tick of the counters gets the summary alone.
///
/// "Others" is the busy time less this process's own: the two clocks differ
/// in granularity (ticks against microseconds), so a small negative
/// difference means none and is reported as zero, and on a run of a few
/// ticks the benchmark's own share may read slightly above what the ticks
/// count as busy (over 100% on the shortest runs).
pub fn shares(before: &CpuCounters, after: &CpuCounters) -> Value {
    let d = |i: usize| after.ticks[i].saturating_sub(before.ticks[i]) as f64 / after.ticks_per_s;
    let total: f64 = (0..COLUMNS).map(d).sum();
    if total <= 0.0 {
        // A run shorter than the counters' tick has no shares to give.
        return json!({
            "cpu_seconds": 0.0,
            "summary": "shorter than one tick of the kernel's CPU counters: no shares",
        });
    }
    let busy = d(USER) + d(NICE) + d(SYSTEM) + d(IRQ) + d(SOFTIRQ);
    let own = (after.own_s - before.own_s).max(0.0);
    let others = (busy - own).max(0.0);
    let steal = d(STEAL);
    let idle = d(IDLE) + d(IOWAIT);
    let pct = |x: f64| 100.0 * x / total;
    json!({
        "cpu_seconds": total,
        "this_benchmark": own / total,
        "other_processes": others / total,
        "hypervisor_steal": steal / total,
        "idle": idle / total,
        "summary": format!(
            "of {total:.1} CPU-seconds: this benchmark {:.1}%, other processes {:.1}%, hypervisor steal {:.1}%, idle {:.1}%",
            pct(own),
            pct(others),
            pct(steal),
            pct(idle)
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const STAT: &str =
        "cpu  100 5 20 1000 10 1 2 3 0 0\ncpu0 50 2 10 500 5 0 1 1 0 0\nintr 1 2 3\n";

    #[test]
    fn the_aggregate_line_is_read_and_per_cpu_lines_are_not() {
        assert_eq!(parse_stat(STAT), Some([100, 5, 20, 1000, 10, 1, 2, 3]));
        assert_eq!(parse_stat("cpu0 1 2 3 4 5 6 7 8\n"), None);
        assert_eq!(parse_stat("cpu 1 2 3\n"), None, "too few columns");
        assert_eq!(parse_stat("cpu 1 2 x 4 5 6 7 8\n"), None);
        assert_eq!(parse_stat(""), None);
    }

    fn counters(ticks: [u64; COLUMNS], own_s: f64) -> CpuCounters {
        CpuCounters {
            ticks,
            ticks_per_s: 100.0,
            own_s,
        }
    }

    #[test]
    fn time_divides_among_the_benchmark_others_steal_and_idle() {
        let before = counters([0; COLUMNS], 10.0);
        // 10 s of 2 CPUs: 15 s busy (user 12, system 3), 1 s steal, 4 s idle.
        let after = counters([1200, 0, 300, 350, 50, 0, 0, 100], 23.0);
        let s = shares(&before, &after);
        let f = |k: &str| s[k].as_f64().unwrap();
        assert!((f("cpu_seconds") - 20.0).abs() < 1e-9);
        assert!((f("this_benchmark") - 13.0 / 20.0).abs() < 1e-9);
        assert!((f("other_processes") - 2.0 / 20.0).abs() < 1e-9);
        assert!((f("hypervisor_steal") - 1.0 / 20.0).abs() < 1e-9);
        assert!((f("idle") - 4.0 / 20.0).abs() < 1e-9);
        let summary = s["summary"].as_str().unwrap();
        assert!(summary.contains("other processes 10.0%"), "{summary}");
        assert!(summary.contains("hypervisor steal 5.0%"), "{summary}");
    }

    #[test]
    fn own_time_above_the_busy_ticks_leaves_no_negative_others() {
        let before = counters([0; COLUMNS], 0.0);
        let after = counters([100, 0, 0, 100, 0, 0, 0, 0], 1.05);
        let s = shares(&before, &after);
        assert_eq!(s["other_processes"].as_f64(), Some(0.0));
        let none = shares(&after, &after);
        assert_eq!(none["cpu_seconds"].as_f64(), Some(0.0), "no time elapsed");
        assert!(none.get("other_processes").is_none(), "no shares: {none}");
    }

    #[test]
    fn a_busy_loop_here_is_counted_as_this_benchmarks_time() {
        let Some(before) = read() else {
            return; // no /proc/stat on this platform
        };
        let start = std::time::Instant::now();
        let mut x = 0u64;
        while start.elapsed().as_millis() < 300 {
            x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
        }
        let after = read().unwrap();
        assert!(
            after.own_s - before.own_s >= 0.25,
            "own CPU time counts the loop"
        );
        let s = shares(&before, &after);
        assert!(s["this_benchmark"].as_f64().unwrap() > 0.0);
    }
}
