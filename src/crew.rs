//! A fixed crew of threads for work inside one frame, without allocating per frame.
//!
//! A [`Crew`] keeps `n` states, one per member: the calling thread is member 0 and `n - 1`
//! threads, started once, are the others. [`Crew::run`] hands every member the same job (a
//! closure that borrows the caller's data) with its own state and its index, and returns when all
//! have finished. Nothing is allocated per call (a mutex and two condition variables), unlike a
//! general-purpose pool, whose job queue allocates now and then: the trackers' hot path does not
//! allocate (`tests/it/alloc.rs`). What a job computes goes into the members' states, which
//! [`Crew::states`] reads afterwards.
//!
//! Which member does what depends only on the index, so a job that splits its work by the index
//! and keeps it independent gives the same result with any number of members.

use std::panic::{AssertUnwindSafe, catch_unwind, resume_unwind};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A job: runs on a member's state with the member's index.
type Job<'a, S> = dyn Fn(&mut S, usize) + Sync + 'a;

/// What the caller and the members share.
struct Shared<S> {
    control: Mutex<Control<S>>,
    /// Rung when a job is posted or the crew disbands.
    start: Condvar,
    /// Rung when the last member finishes a job.
    done: Condvar,
    /// The members' states (member 0's too); a member holds its own while it works.
    states: Vec<Mutex<S>>,
    /// Copies of `Control::generation` and `Control::pending`, read without the lock while a
    /// thread spins briefly before it sleeps (a wake-up through the condition variable costs
    /// tens of microseconds on a virtual machine); the locked values decide.
    posted: AtomicU64,
    remaining: AtomicUsize,
}

/// How long a thread spins on `posted` or `remaining` before it sleeps.
const SPIN: Duration = Duration::from_micros(50);

/// Spins until `done()` or [`SPIN`] has passed.
fn spin_until(done: impl Fn() -> bool) {
    let start = Instant::now();
    while !done() {
        for _ in 0..64 {
            std::hint::spin_loop();
        }
        if start.elapsed() > SPIN {
            return;
        }
    }
}

struct Control<S> {
    /// Counts the jobs posted; a member runs each generation once.
    generation: u64,
    /// The current job, with its lifetime erased: valid while `pending > 0` (see `run`).
    job: Option<*const Job<'static, S>>,
    /// Members (other than the caller) that have not finished the current job.
    pending: usize,
    /// A member's job panicked.
    panicked: bool,
    quit: bool,
}

// SAFETY: the job pointer is only dereferenced while `Crew::run`, which owns the borrow it was
// made from, waits for the members; the closure is `Sync`, so sharing it between threads is sound.
unsafe impl<S: Send> Send for Control<S> {}

/// A fixed set of threads, each with a state of type `S`.
pub struct Crew<S: Send + 'static> {
    shared: Arc<Shared<S>>,
    threads: Vec<JoinHandle<()>>,
}

impl<S: Send + 'static> std::fmt::Debug for Crew<S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Crew")
            .field("members", &self.shared.states.len())
            .finish()
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A job that panicked is reported by `run`; the data under the locks stays usable.
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The number of threads a setting of `threads` means: `0` is every core.
pub fn threads_for(threads: usize) -> usize {
    match threads {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        t => t,
    }
}

impl<S: Send + 'static> Crew<S> {
    /// A crew of `states.len()` members (at least one), the calling thread being the first:
    /// starts `states.len() - 1` threads.
    ///
    /// # Panics
    /// If `states` is empty, or a thread cannot be started ([`Crew::try_new`] returns that
    /// error instead).
    pub fn new(states: Vec<S>) -> Self {
        Self::try_new(states).expect("cannot start a thread")
    }

    /// [`Crew::try_new`], a failure to start a thread as the library's error.
    pub fn start(states: Vec<S>) -> crate::error::Result<Self> {
        let threads = states.len();
        Self::try_new(states).map_err(|e| crate::error::Error::Threads {
            threads,
            message: e.to_string(),
        })
    }

    /// [`Crew::new`], with the error of a thread that cannot be started (the threads already
    /// started are stopped).
    ///
    /// # Panics
    /// If `states` is empty.
    pub fn try_new(states: Vec<S>) -> std::io::Result<Self> {
        assert!(!states.is_empty(), "a crew needs at least one member");
        let n = states.len();
        let shared = Arc::new(Shared {
            control: Mutex::new(Control {
                generation: 0,
                job: None,
                pending: 0,
                panicked: false,
                quit: false,
            }),
            start: Condvar::new(),
            done: Condvar::new(),
            states: states.into_iter().map(Mutex::new).collect(),
            posted: AtomicU64::new(0),
            remaining: AtomicUsize::new(0),
        });
        let mut crew = Crew {
            shared,
            threads: Vec::with_capacity(n - 1),
        };
        for index in 1..n {
            let shared = Arc::clone(&crew.shared);
            // On an error, dropping `crew` stops the members started so far.
            let thread = std::thread::Builder::new()
                .name(format!("regtrack-crew-{index}"))
                .spawn(move || member(&shared, index))?;
            crew.threads.push(thread);
        }
        Ok(crew)
    }

    /// The number of members, the calling thread included.
    pub fn len(&self) -> usize {
        self.shared.states.len()
    }

    /// Whether the crew is empty (never: it has the calling thread).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Runs `job` on every member (its state and index, `0..len()`); returns when all have
    /// finished. A panic in any member's job is raised here, after all have finished.
    pub fn run(&mut self, job: &(dyn Fn(&mut S, usize) + Sync)) {
        if self.threads.is_empty() {
            job(&mut lock(&self.shared.states[0]), 0);
            return;
        }
        let erased: *const Job<'_, S> = job;
        // SAFETY: only the lifetime changes; the pointer is used by the members only until
        // `pending` is back to zero, which this function waits for before it returns (also
        // when the caller's own share panics).
        let erased: *const Job<'static, S> = unsafe { std::mem::transmute(erased) };
        {
            let mut c = lock(&self.shared.control);
            c.job = Some(erased);
            c.pending = self.threads.len();
            c.panicked = false;
            c.generation += 1;
            self.shared
                .remaining
                .store(self.threads.len(), Ordering::Release);
            self.shared.posted.store(c.generation, Ordering::Release);
        }
        self.shared.start.notify_all();
        let own = catch_unwind(AssertUnwindSafe(|| {
            job(&mut lock(&self.shared.states[0]), 0)
        }));
        spin_until(|| self.shared.remaining.load(Ordering::Acquire) == 0);
        let panicked = {
            let mut c = lock(&self.shared.control);
            while c.pending > 0 {
                c = self
                    .shared
                    .done
                    .wait(c)
                    .unwrap_or_else(PoisonError::into_inner);
            }
            c.job = None;
            c.panicked
        };
        if let Err(payload) = own {
            resume_unwind(payload);
        }
        assert!(!panicked, "a crew member's job panicked");
    }

    /// `out[i] = f(state, i)` for every `i`, the indices shared among the members in blocks of
    /// `block` (each member with its own state): the same result on any number of members when
    /// `f` depends only on `i` (the state is scratch).
    pub fn fill<T: Send>(
        &mut self,
        out: &mut [T],
        block: usize,
        f: &(dyn Fn(&mut S, usize) -> T + Sync),
    ) {
        let shares = Shares::new(out, block, self.len());
        self.run(&|state, member| {
            while let Some((start, part)) = shares.take(member) {
                for (k, o) in part.iter_mut().enumerate() {
                    *o = f(state, start + k);
                }
            }
        });
    }

    /// Each member's state, in the order of their indices (between runs).
    pub fn states(&mut self) -> impl Iterator<Item = MutexGuard<'_, S>> {
        self.shared.states.iter().map(|s| lock(s))
    }
}

/// Parts a [`Shares`] keeps its own cursor for (more members share parts).
const MAX_PARTS: usize = 8;

/// A slice handed out in blocks, each block once, so the members of a crew can each take `&mut`
/// blocks of the same slice as they become free (work that costs unevenly spreads evenly)
/// without locks. The blocks are split into as many contiguous parts as members: a member takes
/// its own part's blocks first, in order, then helps with the others'. Work on neighbouring
/// items (rows of a frame, patches in raster order) thus stays with the member whose core
/// holds their data in its cache from the last time (on a virtual machine the two cores may
/// share no cache: data one wrote, the other fetches from far).
pub struct Shares<'a, T> {
    ptr: *mut T,
    len: usize,
    block: usize,
    blocks: usize,
    parts: usize,
    /// Per part, the next block to hand out (past the part's end once it is done).
    next: [AtomicUsize; MAX_PARTS],
    _items: std::marker::PhantomData<&'a mut [T]>,
}

// SAFETY: `Shares` hands out disjoint `&mut [T]` (each block index once, through the atomic
// counters of disjoint parts), so sharing it between threads is sharing `&mut` borrows of `T`
// across threads, which `T: Send` allows.
unsafe impl<T: Send> Sync for Shares<'_, T> {}
unsafe impl<T: Send> Send for Shares<'_, T> {}

impl<'a, T> Shares<'a, T> {
    /// `items` in blocks of `block` (at least 1) items, the last maybe shorter, in `parts`
    /// parts (at least one; usually the crew's [`Crew::len`]).
    pub fn new(items: &'a mut [T], block: usize, parts: usize) -> Self {
        let block = block.max(1);
        let blocks = items.len().div_ceil(block);
        let parts = parts.clamp(1, MAX_PARTS);
        Shares {
            ptr: items.as_mut_ptr(),
            len: items.len(),
            block,
            blocks,
            parts,
            next: std::array::from_fn(|p| AtomicUsize::new(p * blocks / parts)),
            _items: std::marker::PhantomData,
        }
    }

    /// The next block nobody took yet, for member `member` (its own part first), with the index
    /// of its first item; `None` when all are taken.
    pub fn take(&self, member: usize) -> Option<(usize, &'a mut [T])> {
        let own = member % self.parts;
        for k in 0..self.parts {
            let p = (own + k) % self.parts;
            let end = (p + 1) * self.blocks / self.parts;
            if self.next[p].load(Ordering::Relaxed) >= end {
                continue;
            }
            let b = self.next[p].fetch_add(1, Ordering::Relaxed);
            if b >= end {
                continue;
            }
            let start = b * self.block;
            let n = self.block.min(self.len - start);
            // SAFETY: `b < end <= blocks`, so `start < len` and `start + n <= len`, inside the
            // slice borrowed for 'a; block `b` lies in part `p` only and is returned once (the
            // part's counter only grows), and blocks do not overlap.
            return Some((start, unsafe {
                std::slice::from_raw_parts_mut(self.ptr.add(start), n)
            }));
        }
        None
    }
}

/// A member's loop: waits for a job, runs it on its state, reports, until the crew disbands.
fn member<S: Send>(shared: &Shared<S>, index: usize) {
    let mut seen = 0;
    loop {
        spin_until(|| shared.posted.load(Ordering::Acquire) != seen);
        let job = {
            let mut c = lock(&shared.control);
            while c.generation == seen && !c.quit {
                c = shared.start.wait(c).unwrap_or_else(PoisonError::into_inner);
            }
            if c.quit {
                return;
            }
            seen = c.generation;
            c.job
        };
        let result = catch_unwind(AssertUnwindSafe(|| {
            if let Some(job) = job {
                // SAFETY: `run` keeps the job alive until this member reports below.
                let job = unsafe { &*job };
                job(&mut lock(&shared.states[index]), index);
            }
        }));
        let mut c = lock(&shared.control);
        c.panicked |= result.is_err();
        c.pending -= 1;
        shared.remaining.store(c.pending, Ordering::Release);
        if c.pending == 0 {
            shared.done.notify_all();
        }
    }
}

impl<S: Send + 'static> Drop for Crew<S> {
    fn drop(&mut self) {
        lock(&self.shared.control).quit = true;
        self.shared.start.notify_all();
        for t in self.threads.drain(..) {
            // A member that panicked has reported it already.
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fill_gives_each_index_its_value_on_any_number_of_members() {
        for n in 1..=3 {
            let mut crew = Crew::new(vec![0usize; n]);
            let mut out = vec![0u64; 1000];
            crew.fill(&mut out, 7, &|calls, i| {
                *calls += 1;
                (i as u64) * (i as u64)
            });
            assert!(out.iter().enumerate().all(|(i, &v)| v == (i * i) as u64));
            assert_eq!(crew.states().map(|s| *s).sum::<usize>(), 1000);
        }
    }

    #[test]
    fn every_member_runs_each_job_once_on_its_own_state() {
        for n in 1..=4 {
            let mut crew = Crew::new(vec![Vec::<usize>::new(); n]);
            let data: Vec<usize> = (0..100).collect();
            for round in 0..50 {
                crew.run(&|s: &mut Vec<usize>, k| {
                    // Member k takes every n-th item from k.
                    s.clear();
                    s.extend(data.iter().skip(k).step_by(n).map(|v| v * round));
                });
                let mut all: Vec<usize> = crew.states().flat_map(|s| s.clone()).collect();
                all.sort();
                assert_eq!(all, data.iter().map(|v| v * round).collect::<Vec<_>>());
            }
            assert_eq!(crew.len(), n);
        }
    }

    #[test]
    fn shares_hand_every_block_out_once() {
        for n in 1..=3 {
            let mut crew = Crew::new(vec![0usize; n]);
            let mut items = vec![0u32; 1001];
            for round in 1..=20u32 {
                let shares = Shares::new(&mut items, 16, n);
                crew.run(&|taken: &mut usize, m| {
                    while let Some((start, block)) = shares.take(m) {
                        assert_eq!(start % 16, 0);
                        for v in block.iter_mut() {
                            *v += 1;
                        }
                        *taken += 1;
                    }
                });
                assert!((0..n).all(|m| shares.take(m).is_none()));
                assert!(items.iter().all(|&v| v == round));
            }
            assert_eq!(crew.states().map(|s| *s).sum::<usize>(), 20 * 63);
        }
    }

    #[test]
    fn shares_give_each_member_its_own_part_first() {
        // 10 items in blocks of 2: 5 blocks, parts [0, 2) and [2, 5).
        let mut items = [0u8; 10];
        let shares = Shares::new(&mut items, 2, 2);
        let first = |m| shares.take(m).map(|(start, b)| (start, b.len()));
        assert_eq!(first(1), Some((4, 2)));
        assert_eq!(first(0), Some((0, 2)));
        assert_eq!(first(0), Some((2, 2)));
        // Member 0's part is done: it helps with member 1's.
        assert_eq!(first(0), Some((6, 2)));
        assert_eq!(first(1), Some((8, 2)));
        assert_eq!(first(1), None);
        assert_eq!(first(0), None);
        // More members than blocks: the parts that are empty send their members to the others.
        let mut few = [0u8; 3];
        let shares = Shares::new(&mut few, 1, 8);
        let mut got: Vec<usize> = (0..8)
            .filter_map(|m| shares.take(m).map(|(s, _)| s))
            .collect();
        got.sort_unstable();
        assert_eq!(got, [0, 1, 2]);
    }

    #[test]
    fn a_member_that_panics_is_reported_and_the_crew_goes_on() {
        let mut crew = Crew::new(vec![0usize; 2]);
        let r = catch_unwind(AssertUnwindSafe(|| {
            crew.run(&|_: &mut usize, k| assert!(k == 0, "member {k} fails"))
        }));
        assert!(r.is_err());
        crew.run(&|s: &mut usize, k| *s = k + 1);
        assert_eq!(crew.states().map(|s| *s).collect::<Vec<_>>(), [1, 2]);
    }
}
