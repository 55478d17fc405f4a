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
//!
//! Wait slots (`--wait-slots`, default `--jobs`): renders that mostly wait
//! (a backend's measured `waits_below`: POV-Ray under 2,500 triangles keeps a
//! core busy a fifth of its wall time at most, the rest is its front end's
//! polling sleeps) also run on extra slots of their own, taken cheapest first
//! from the far end of the order, so that their sleeping no longer holds a
//! CPU slot. N wait slots take at most N/5 cores from the CPU slots.

use std::sync::atomic::Ordering;
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
    /// Renders in flight at most on the CPU slots.
    pub jobs: usize,
    /// Extra slots that take only renders that mostly wait (module docs); 0:
    /// every render holds one of the `jobs` slots.
    pub wait_slots: usize,
    /// Bytes of estimated peak memory in flight at most (see [`Budget`]).
    pub memory_budget: Bytes,
}

/// Which item a slot takes next: a CPU slot the costliest not yet taken, a
/// wait slot the cheapest not yet taken of those that wait.
struct Queue {
    /// Positions in the cost order already taken.
    taken: Vec<bool>,
    /// Every position before this one is taken.
    front: usize,
}

impl Queue {
    fn take(&mut self, wait_slot: bool, waits: impl Fn(usize) -> bool) -> Option<usize> {
        if wait_slot {
            let k = (self.front..self.taken.len())
                .rev()
                .find(|&k| !self.taken[k] && waits(k))?;
            self.taken[k] = true;
            return Some(k);
        }
        while self.taken.get(self.front) == Some(&true) {
            self.front += 1;
        }
        let k = self.front;
        *self.taken.get_mut(k)? = true;
        Some(k)
    }
}

/// Runs `f` on every item on `jobs` scoped threads plus `wait_slots` threads
/// that take only items for which `waits` is true, each thread owning a slot
/// state made by `new_slot` (its workers); CPU slots take items in decreasing
/// `cost` (ties in item order), wait slots from the other end, all admitted by
/// `memory`. Results come back in item order, so records keep the order of a
/// sequential run.
///
/// A panic in `f` is a bug: its memory share is released, no slot starts
/// another item, the renders in flight finish, and the first panic is then
/// resumed with its own payload (a slot's state may be half-updated, so the
/// pool does not go on with it; nothing waits forever, nothing is hidden).
pub fn run<T: Sync, R: Send, S>(
    opts: PoolOptions,
    items: &[T],
    cost: impl Fn(&T) -> f64,
    waits: impl Fn(&T) -> bool + Sync,
    memory: impl Fn(&T) -> Bytes + Sync,
    new_slot: impl Fn(usize) -> S + Sync,
    f: impl Fn(&mut S, &T) -> R + Sync,
) -> Vec<R> {
    let jobs = opts.jobs.clamp(1, items.len().max(1));
    let waiting = items.iter().filter(|t| waits(t)).count();
    let wait_slots = opts.wait_slots.min(waiting);
    let mut order: Vec<usize> = (0..items.len()).collect();
    order.sort_by(|&a, &b| cost(&items[b]).total_cmp(&cost(&items[a])));
    let queue = Mutex::new(Queue {
        taken: vec![false; items.len()],
        front: 0,
    });
    let budget = Budget {
        limit: opts.memory_budget,
        in_flight: Mutex::new(0),
        freed: Condvar::new(),
    };
    let out: Mutex<Vec<Option<R>>> = Mutex::new((0..items.len()).map(|_| None).collect());
    let panicked: Mutex<Option<Box<dyn std::any::Any + Send>>> = Mutex::new(None);
    let stop = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        for slot_index in 0..jobs + wait_slots {
            let (order, queue, budget, out) = (&order, &queue, &budget, &out);
            let (new_slot, f, memory, waits) = (&new_slot, &f, &memory, &waits);
            let (panicked, stop) = (&panicked, &stop);
            let wait_slot = slot_index >= jobs;
            s.spawn(move || {
                let mut slot = new_slot(slot_index);
                while !stop.load(Ordering::Acquire) {
                    let next = queue
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .take(wait_slot, |k| waits(&items[order[k]]));
                    let Some(k) = next else { break };
                    let i = order[k];
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
    use std::sync::atomic::AtomicUsize;
    use std::time::Duration;

    /// `jobs` CPU slots, no wait slots, `memory_budget` bytes.
    fn cpu_slots(jobs: usize, memory_budget: u64) -> PoolOptions {
        PoolOptions {
            jobs,
            wait_slots: 0,
            memory_budget,
        }
    }

    #[test]
    fn results_keep_item_order_and_biggest_start_first() {
        let started = Mutex::new(Vec::new());
        let items = [1.0, 5.0, 3.0, 4.0];
        let opts = cpu_slots(1, u64::MAX);
        let out = run(
            opts,
            &items,
            |x| *x,
            |_| false,
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
        let opts = cpu_slots(4, memory_budget);
        run(
            opts,
            items,
            |_| 1.0,
            |_| false,
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
        let opts = cpu_slots(2, 10);
        let out = run(
            opts,
            &items,
            |m| *m as f64,
            |_| false,
            |m| *m,
            |_| (),
            |_, m| *m,
        );
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
                let opts = cpu_slots(2, 10);
                run(
                    opts,
                    &items,
                    |_| 1.0,
                    |_| false,
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
        let opts = cpu_slots(3, u64::MAX);
        let out = run(
            opts,
            &items,
            |_| 0.0,
            |_| false,
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

    /// Items (cost, waits) on one CPU slot and two wait slots, each taking
    /// 40 ms: the most in flight at once, of those that do not wait and of all.
    fn peaks_with_wait_slots(items: &[(f64, bool)]) -> (usize, usize, Vec<usize>) {
        let busy = AtomicUsize::new(0);
        let all = AtomicUsize::new(0);
        let (peak_busy, peak_all) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let opts = PoolOptions {
            jobs: 1,
            wait_slots: 2,
            memory_budget: u64::MAX,
        };
        let out = run(
            opts,
            items,
            |t| t.0,
            |t| t.1,
            |_| 0,
            |i| i,
            |slot, t| {
                let counters: &[(&AtomicUsize, &AtomicUsize)] = if t.1 {
                    &[(&all, &peak_all)]
                } else {
                    &[(&busy, &peak_busy), (&all, &peak_all)]
                };
                for (now, peak) in counters {
                    peak.fetch_max(now.fetch_add(1, Ordering::SeqCst) + 1, Ordering::SeqCst);
                }
                std::thread::sleep(Duration::from_millis(40));
                for (now, _) in counters {
                    now.fetch_sub(1, Ordering::SeqCst);
                }
                assert!(
                    *slot == 0 || t.1,
                    "a wait slot took a render that does not wait"
                );
                *slot
            },
        );
        (peak_busy.into_inner(), peak_all.into_inner(), out)
    }

    #[test]
    fn wait_slots_take_only_waiting_renders_and_run_them_beside_the_others() {
        let items: Vec<(f64, bool)> = (0..12).map(|i| (i as f64, i % 2 == 0)).collect();
        let (busy, all, slots) = peaks_with_wait_slots(&items);
        // The renders that do not wait still run one at a time (one CPU slot) ...
        assert_eq!(busy, 1);
        // ... while waiting ones run beside them on the wait slots.
        assert!(all >= 2, "nothing ran beside the CPU slot");
        assert!(slots.iter().any(|&s| s > 0));
        // Without waiting renders the wait slots take nothing.
        let none: Vec<(f64, bool)> = (0..4).map(|i| (i as f64, false)).collect();
        let (busy, all, slots) = peaks_with_wait_slots(&none);
        assert_eq!((busy, all), (1, 1));
        assert!(slots.iter().all(|&s| s == 0));
    }

    #[test]
    fn the_queue_gives_cpu_slots_the_front_and_wait_slots_the_cheapest_waiting() {
        let waits = [false, true, false, true, true, false];
        let mut q = Queue {
            taken: vec![false; waits.len()],
            front: 0,
        };
        assert_eq!(q.take(true, |k| waits[k]), Some(4));
        assert_eq!(q.take(false, |k| waits[k]), Some(0));
        assert_eq!(q.take(true, |k| waits[k]), Some(3));
        assert_eq!(q.take(false, |k| waits[k]), Some(1));
        assert_eq!(q.take(false, |k| waits[k]), Some(2));
        assert_eq!(q.take(true, |k| waits[k]), None);
        assert_eq!(q.take(false, |k| waits[k]), Some(5));
        assert_eq!(q.take(false, |k| waits[k]), None);
        assert!(q.taken.iter().all(|&t| t));
    }
}
