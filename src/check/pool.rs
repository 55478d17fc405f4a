//! The job pool of a check run's external renders: `--jobs` slots, each with
//! its own long-lived harness workers (`worker.rs`), taking renders longest
//! first, and never starting a render whose estimated memory would push the
//! renders in flight past the memory budget (`--memory-budget`).
//!
//! Why these rules: external renders are independent processes, so they can
//! run side by side; most of a small one's time is start-up and sleeping
//! (POV-Ray's front end polls), which side-by-side runs overlap. Taking the
//! biggest first keeps one large scene from finishing alone at the end. The
//! core's own multi-threaded renders run before the pool starts, so the pool
//! never competes with them for the cores.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};

/// Bytes a render is expected to need at its peak.
pub type Bytes = u64;

/// Peak resident memory of one external render of a scene with `triangles`
/// triangles, from the backend's declaration `(fixed bytes, bytes per
/// triangle)`: each harness backend measures its own (`PEAK_MEMORY` beside
/// it, reported by `info --json`), so this module names no renderer.
pub fn render_memory((fixed, per_triangle): (u64, u64), triangles: u64) -> Bytes {
    fixed.saturating_add(per_triangle.saturating_mul(triangles))
}

/// The default memory budget: half of what the system reports available
/// (`MemAvailable`), or 4 GiB where that cannot be read.
pub fn default_memory_budget() -> Bytes {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find_map(|l| l.strip_prefix("MemAvailable:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        })
        .map(|kib| kib * 1024 / 2)
        .unwrap_or(4 << 30)
}

/// Admission by memory: a render starts when the estimates of those in
/// flight plus its own fit the budget, or when nothing else is in flight
/// (a render bigger than the budget still runs, alone).
struct Budget {
    limit: Bytes,
    in_flight: Mutex<Bytes>,
    freed: Condvar,
}

impl Budget {
    /// Waits until `need` fits and takes it; what is taken is given back when
    /// the returned guard drops, so a render that panics releases its share
    /// too (a panic used to keep it, and every render waiting on the budget
    /// then waited forever).
    fn acquire(&self, need: Bytes) -> Held<'_> {
        let mut used = self.in_flight.lock().unwrap_or_else(|e| e.into_inner());
        while *used > 0 && used.saturating_add(need) > self.limit {
            used = self.freed.wait(used).unwrap_or_else(|e| e.into_inner());
        }
        *used += need;
        Held { budget: self, need }
    }
}

/// A render's share of the [`Budget`], released on drop (unwinding included).
struct Held<'a> {
    budget: &'a Budget,
    need: Bytes,
}

impl Drop for Held<'_> {
    fn drop(&mut self) {
        let mut used = self
            .budget
            .in_flight
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        *used = used.saturating_sub(self.need);
        self.budget.freed.notify_all();
    }
}

/// How the pool runs: slots, memory budget.
#[derive(Debug, Clone, Copy)]
pub struct PoolOptions {
    /// Renders in flight at most.
    pub jobs: usize,
    /// Bytes of estimated peak memory in flight at most (see [`Budget`]).
    pub memory_budget: Bytes,
}

/// Runs `f` on every item on `jobs` scoped threads, each owning a slot state
/// made by `new_slot` (its workers); items are taken in decreasing `cost`
/// (ties in item order) and admitted by `memory`. Results come back in item
/// order, so records keep the order of a sequential run.
///
/// A panic in `f` is a bug: its memory share is released, no slot starts
/// another item, the renders in flight finish, and the first panic is then
/// resumed with its own payload (a slot's state may be half-updated, so the
/// pool does not go on with it; nothing waits forever, nothing is hidden).
pub fn run<T: Sync, R: Send, S>(
    opts: PoolOptions,
    items: &[T],
    cost: impl Fn(&T) -> f64,
    memory: impl Fn(&T) -> Bytes + Sync,
    new_slot: impl Fn(usize) -> S + Sync,
    f: impl Fn(&mut S, &T) -> R + Sync,
) -> Vec<R> {
    let jobs = opts.jobs.clamp(1, items.len().max(1));
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|&a, &b| cost(&items[b]).total_cmp(&cost(&items[a])));
    let next = AtomicUsize::new(0);
    let budget = Budget {
        limit: opts.memory_budget,
        in_flight: Mutex::new(0),
        freed: Condvar::new(),
    };
    let out: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    let panicked: Mutex<Option<Box<dyn std::any::Any + Send>>> = Mutex::new(None);
    let stop = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        for slot_index in 0..jobs {
            let (order, next, budget, out) = (&order, &next, &budget, &out);
            let (new_slot, f, memory) = (&new_slot, &f, &memory);
            let (panicked, stop) = (&panicked, &stop);
            s.spawn(move || {
                let mut slot = new_slot(slot_index);
                while !stop.load(Ordering::Acquire) {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&i) = order.get(k) else { break };
                    let need = memory(&items[i]);
                    let held = budget.acquire(need);
                    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        f(&mut slot, &items[i])
                    }));
                    drop(held);
                    match r {
                        Ok(r) => out.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r),
                        Err(payload) => {
                            stop.store(true, Ordering::Release);
                            panicked
                                .lock()
                                .unwrap_or_else(|e| e.into_inner())
                                .get_or_insert(payload);
                            break;
                        }
                    }
                }
            });
        }
    });
    if let Some(payload) = panicked.into_inner().unwrap_or_else(|e| e.into_inner()) {
        std::panic::resume_unwind(payload);
    }
    out.into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.expect("every item ran"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn results_keep_item_order_and_biggest_start_first() {
        let started = Mutex::new(Vec::new());
        let items = [1.0, 5.0, 3.0, 4.0];
        let opts = PoolOptions {
            jobs: 1,
            memory_budget: u64::MAX,
        };
        let out = run(
            opts,
            &items,
            |x| *x,
            |_| 0,
            |_| (),
            |_, x| {
                started.lock().unwrap().push(*x);
                x * 2.0
            },
        );
        assert_eq!(out, vec![2.0, 10.0, 6.0, 8.0]);
        assert_eq!(*started.lock().unwrap(), vec![5.0, 4.0, 3.0, 1.0]);
    }

    /// The most renders in flight at once when `items` (their sizes) run on
    /// 4 slots under `memory_budget`, each taking `ms` milliseconds.
    fn peak_in_flight(items: &[u64], memory_budget: u64, ms: u64) -> usize {
        let in_flight = AtomicUsize::new(0);
        let peak = AtomicUsize::new(0);
        let opts = PoolOptions {
            jobs: 4,
            memory_budget,
        };
        run(
            opts,
            items,
            |_| 1.0,
            |m| *m,
            |_| (),
            |_, _| {
                let now = in_flight.fetch_add(1, Ordering::SeqCst) + 1;
                peak.fetch_max(now, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(ms));
                in_flight.fetch_sub(1, Ordering::SeqCst);
            },
        );
        peak.load(Ordering::SeqCst)
    }

    #[test]
    fn the_memory_budget_keeps_big_renders_apart() {
        // Four renders of 6 units under a budget of 10, on 4 slots: never two at once.
        assert_eq!(peak_in_flight(&[6; 4], 10, 30), 1);
        // Under a budget that fits two, two run side by side.
        assert_eq!(peak_in_flight(&[6; 4], 12, 50), 2);
    }

    #[test]
    fn a_render_bigger_than_the_budget_still_runs_alone() {
        let items = [100u64, 1];
        let opts = PoolOptions {
            jobs: 2,
            memory_budget: 10,
        };
        let out = run(opts, &items, |m| *m as f64, |m| *m, |_| (), |_, m| *m);
        assert_eq!(out, vec![100, 1]);
    }

    /// A render that panics while holding the memory budget: the others
    /// still get it (no wait forever), and the pool ends with that panic,
    /// its own message, not a generic one or none.
    #[test]
    fn a_panicking_render_releases_its_budget_and_its_panic_is_passed_on() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let got = std::panic::catch_unwind(|| {
                let items = [10u64, 10, 10];
                let opts = PoolOptions {
                    jobs: 2,
                    memory_budget: 10,
                };
                run(
                    opts,
                    &items,
                    |_| 1.0,
                    |m| *m,
                    |_| (),
                    |_, m| {
                        std::thread::sleep(Duration::from_millis(20));
                        if *m == 10 {
                            panic!("render of {m} went wrong");
                        }
                        *m
                    },
                )
            });
            let _ = tx.send(got.map_err(|p| {
                p.downcast_ref::<String>()
                    .cloned()
                    .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default()
            }));
        });
        let got = rx
            .recv_timeout(Duration::from_secs(20))
            .expect("the pool waited forever for the budget a panicked render held");
        assert_eq!(got, Err("render of 10 went wrong".to_string()));
    }

    #[test]
    fn each_slot_keeps_its_own_state() {
        let items: Vec<u32> = (0..20).collect();
        let opts = PoolOptions {
            jobs: 3,
            memory_budget: u64::MAX,
        };
        let out = run(
            opts,
            &items,
            |_| 0.0,
            |_| 0,
            |i| (i, 0u32),
            |slot, _| {
                slot.1 += 1;
                (slot.0, slot.1)
            },
        );
        // Within one slot the counter only grows: no slot's state is shared.
        for s in 0..3 {
            let counts: Vec<u32> = out
                .iter()
                .filter(|(i, _)| *i == s)
                .map(|(_, c)| *c)
                .collect();
            let mut sorted = counts.clone();
            sorted.sort();
            assert_eq!(sorted, (1..=counts.len() as u32).collect::<Vec<_>>());
        }
    }
}
