//! Independent tasks run on the rayon pool in a given order of priority: each free thread takes
//! the next task of one shared list (greedy list scheduling). A parallel iterator over the list
//! would instead split it in halves between the threads, so that one thread can be left with
//! two long tasks while the other runs out of work.

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

/// `run(task)` for every task, each started in list order by whichever thread is free; the
/// results come back in list order.
pub fn in_list_order<T: Sync, R: Send>(tasks: &[T], run: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let next = AtomicUsize::new(0);
    let workers = rayon::current_num_threads().clamp(1, tasks.len().max(1));
    let mut done: Vec<(usize, R)> = (0..workers)
        .into_par_iter()
        .with_max_len(1)
        .flat_map_iter(|_| {
            let mut mine = Vec::new();
            // Each worker stops at the first index past the list: one extra step each.
            loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(task) = tasks.get(i) else { break };
                mine.push((i, run(task)));
            }
            mine
        })
        .collect();
    done.sort_unstable_by_key(|&(i, _)| i);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool")
            .install(f)
    }

    #[test]
    fn every_task_runs_once_and_results_keep_list_order() {
        let tasks: Vec<u64> = (0..37).collect();
        for threads in [1, 2, 5] {
            let runs = AtomicUsize::new(0);
            let out = on_threads(threads, || {
                in_list_order(&tasks, |&t| {
                    runs.fetch_add(1, Ordering::Relaxed);
                    t * t
                })
            });
            assert_eq!(out, tasks.iter().map(|t| t * t).collect::<Vec<_>>());
            assert_eq!(runs.into_inner(), tasks.len(), "{threads} threads");
        }
        assert!(in_list_order(&[] as &[u8], |&t| t).is_empty());
    }

    #[test]
    fn a_free_thread_takes_the_next_task() {
        // Two threads and the tasks [wait for task 1, task 1, slow, slow]. A free thread takes
        // task 1 at once. Split in halves, the second thread would run both slow tasks first
        // and task 0 would give up waiting.
        let (tx, rx) = std::sync::mpsc::channel::<()>();
        let (tx, rx) = (std::sync::Mutex::new(tx), std::sync::Mutex::new(rx));
        let wait = std::time::Duration::from_millis(500);
        let out = on_threads(2, || {
            in_list_order(&[0, 1, 2, 3], |&t| match t {
                0 => rx.lock().unwrap().recv_timeout(wait).is_ok(),
                1 => tx.lock().unwrap().send(()).is_ok(),
                _ => {
                    std::thread::sleep(wait + wait / 5);
                    true
                }
            })
        });
        assert_eq!(out, [true; 4], "task 0 waited in vain for task 1");
    }
}
