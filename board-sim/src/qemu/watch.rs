//! Supervising the running array: the boards' exits, `--kill`, the whole run's deadline
//! and the watchdog on progress. The run never hangs.

use std::time::{Duration, Instant};

use super::options::ArrayOptions;
use super::relay::{Activity, GlobalSwitch};
use super::start::Emulated;

/// Watches until every board's QEMU has exited: ends one on `--kill` (counted from when
/// every board had begun), and every one at the deadline or after `quiet_limit` without a
/// byte on any link, global port or console.
pub(crate) fn watch(
    boards: &mut [Emulated],
    switch: &GlobalSwitch,
    act: &Activity,
    start: Instant,
    quiet_limit: Duration,
    opts: &ArrayOptions,
) {
    let (mut last_activity, mut last_seen) = (act.get(), Instant::now());
    // When every board had told the host its compilation id (before its step 0): the run
    // has begun, and `--kill` counts from there.
    let mut begun: Option<Instant> = None;
    loop {
        let now = Instant::now();
        let t = now.duration_since(start);
        if begun.is_none() && switch.hellos() >= boards.len() {
            begun = Some(now);
        }
        if running(boards, t) == 0 {
            break;
        }
        if act.get() != last_activity {
            (last_activity, last_seen) = (act.get(), now);
        }
        let end_all = if t > opts.deadline {
            Some(format!(
                "still running at the run's deadline ({:.0} s): ended by the harness",
                opts.deadline.as_secs_f64()
            ))
        } else if now.duration_since(last_seen) > quiet_limit {
            Some(format!(
                "no byte on any link, global port or console for {:.0} s (twice the boards' link timeout and more): ended by the harness",
                quiet_limit.as_secs_f64()
            ))
        } else {
            None
        };
        for e in boards.iter_mut() {
            if e.exited.is_some() || e.killed.is_some() {
                continue;
            }
            if let Some(w) = end_all.clone().or_else(|| kill_now(e, opts, begun, now, t)) {
                let _ = e.child.kill();
                e.killed = Some(w);
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Notes the boards that exited (at `t` from the start); how many still run.
fn running(boards: &mut [Emulated], t: Duration) -> usize {
    let mut running = 0;
    for e in boards.iter_mut() {
        if e.exited.is_none() {
            match e.child.try_wait() {
                Ok(Some(st)) => e.exited = Some((st.code(), t.as_secs_f64())),
                Ok(None) => running += 1,
                Err(_) => e.exited = Some((None, t.as_secs_f64())),
            }
        }
    }
    running
}

/// Why `--kill` ends board `e` now, if it does.
fn kill_now(
    e: &Emulated,
    opts: &ArrayOptions,
    begun: Option<Instant>,
    now: Instant,
    t: Duration,
) -> Option<String> {
    let (b, after) = opts.kill?;
    let due = begun.is_some_and(|s| now >= s + after);
    if b != e.board || !due {
        return None;
    }
    Some(format!(
        "killed by the harness at {:.2} s, {:.2} s after every board began (--kill)",
        t.as_secs_f64(),
        begun.map_or(0.0, |s| now.duration_since(s).as_secs_f64())
    ))
}
