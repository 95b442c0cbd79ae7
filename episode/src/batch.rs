//! One batch executor for every way episodes run many at a time (`kitchen-r eval`, `collect`,
//! the worker's local evaluation): items over a few threads, each thread with state of its own
//! (a simulator, an oracle) made once and reused from item to item, and every result handed to
//! the calling thread as it finishes.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;

/// Run `work(&mut state, i)` for every `i` in `0..n` on up to `jobs` threads (at least one, at
/// most `n`), each thread making its `state` once with `init`. `done(i, result)` runs on the
/// calling thread as each item finishes, in the order they finish. When `done` returns an error
/// the batch stops: each thread finishes the item in hand and takes no other, and that error is
/// returned.
pub fn run_batch<S, R, E>(
    n: usize,
    jobs: usize,
    init: impl Fn() -> S + Sync,
    work: impl Fn(&mut S, usize) -> R + Sync,
    mut done: impl FnMut(usize, R) -> Result<(), E>,
) -> Result<(), E>
where
    R: Send,
{
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<(usize, R)>();
    std::thread::scope(|scope| {
        for _ in 0..jobs.clamp(1, n.max(1)) {
            let (tx, next, init, work) = (tx.clone(), &next, &init, &work);
            scope.spawn(move || {
                let mut state = init();
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    if i >= n {
                        break;
                    }
                    if tx.send((i, work(&mut state, i))).is_err() {
                        break;
                    }
                }
            });
        }
        drop(tx);
        // Returning drops `rx`: the threads' next send fails and they stop.
        for (i, r) in rx {
            done(i, r)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_runs_once_with_its_threads_state() {
        let mut seen = [0; 50];
        let r: Result<(), ()> = run_batch(
            50,
            3,
            || 0usize,
            |runs, i| {
                *runs += 1;
                (i, *runs)
            },
            |i, (j, _)| {
                assert_eq!(i, j);
                seen[i] += 1;
                Ok(())
            },
        );
        assert!(r.is_ok());
        assert!(seen.iter().all(|&c| c == 1));
    }

    #[test]
    fn an_error_stops_the_batch() {
        let ran = AtomicUsize::new(0);
        let r = run_batch(
            1000,
            2,
            || (),
            |_, i| {
                // Long enough that the threads could not have run every item by the time the
                // calling thread sees item 3 (1,000 items take 0.5 s on 2 threads).
                std::thread::sleep(std::time::Duration::from_millis(1));
                ran.fetch_add(1, Ordering::SeqCst);
                i
            },
            |_, i| if i == 3 { Err("stop") } else { Ok(()) },
        );
        assert_eq!(r, Err("stop"));
        assert!(
            ran.load(Ordering::SeqCst) < 1000,
            "the threads stopped taking items"
        );
    }

    #[test]
    fn no_items_no_work() {
        let r: Result<(), ()> = run_batch(0, 4, || (), |_, _| panic!("no item"), |_, ()| Ok(()));
        assert!(r.is_ok());
    }
}
