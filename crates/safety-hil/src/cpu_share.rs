//! `--cpu-share-s`: the monitor process's CPU share under a 1 kHz setpoint stream, over a window
//! (/proc/<pid>/stat, per thread from /proc/<pid>/task) and over its whole life (wait4's rusage
//! when it is stopped).

use crate::stack::Stack;
use crate::{Args, Res};
use safety_monitor::Cause;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// utime + stime of `pid` from /proc (s).
fn proc_cpu_s(pid: i32) -> Res<f64> {
    let t = std::fs::read_to_string(format!("/proc/{pid}/stat")).map_err(|e| e.to_string())?;
    // Fields after the command name (which may contain spaces) start after the last ')'.
    let rest = &t[t.rfind(')').ok_or("bad /proc stat")? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| -> Res<f64> {
        f.get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .ok_or_else(|| "bad /proc stat field".to_string())
    };
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Ok((ticks(11)? + ticks(12)?) / hz)
}

/// Per-thread (name, utime + stime s) of `pid` from /proc/<pid>/task.
fn threads_cpu_s(pid: i32) -> Res<BTreeMap<String, f64>> {
    let mut out = BTreeMap::new();
    let dir = format!("/proc/{pid}/task");
    for e in std::fs::read_dir(&dir).map_err(|e| format!("{dir}: {e}"))? {
        let p = e.map_err(|e| e.to_string())?.path();
        let Ok(t) = std::fs::read_to_string(p.join("stat")) else {
            continue;
        };
        let (Some(a), Some(b)) = (t.find('('), t.rfind(')')) else {
            continue;
        };
        let name = t[a + 1..b].to_string();
        let f: Vec<&str> = t[b + 2..].split_whitespace().collect();
        let v = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok()).unwrap_or(0.0);
        // SAFETY: sysconf has no preconditions.
        let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
        *out.entry(name).or_insert(0.0) += (v(11) + v(12)) / hz;
    }
    Ok(out)
}

pub fn cpu_share(args: &Args, secs: f64) -> Res<String> {
    let mut st = Stack::start(
        "cpu_share",
        &args.workdir,
        args.bin_dir.clone(),
        &crate::bus_mode(args)?,
        args.period_us,
        None,
    )?;
    let spawned = Instant::now();
    let _ = st.fake()?.clone();
    st.wait_following(false)?;
    let pid = st.pid("safety-monitor")?;
    let cpu0 = proc_cpu_s(pid)?;
    let th0 = threads_cpu_s(pid)?;
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < secs {
        std::thread::sleep(Duration::from_millis(200));
        st.poll()?;
    }
    let window = t0.elapsed().as_secs_f64();
    let cpu1 = proc_cpu_s(pid)?;
    let th1 = threads_cpu_s(pid)?;
    let per_thread: Vec<String> = th1
        .iter()
        .map(|(n, c)| {
            let d = c - th0.get(n).copied().unwrap_or(0.0);
            format!("{n} {:.2} %", d / window * 100.0)
        })
        .collect();
    // A trip does not end the measurement (the monitor keeps checking while latched); it is
    // reported: on a loaded, non-real-time host a stall > 32 ms loses setpoints.
    let trips: Vec<String> = st
        .monitor_estops
        .iter()
        .map(|e| format!("{:?}", Cause::from_code(e.detail)))
        .collect();
    // SIGTERM: the monitor stops gracefully and logs its summary; wait4 gives its rusage.
    let ru = st.stop_with_usage("safety-monitor")?;
    let life = spawned.elapsed().as_secs_f64();
    let (user, sys) = (ru.user.as_secs_f64(), ru.system.as_secs_f64());
    let summary = std::fs::read_to_string(st.dir.join("safety-monitor.log"))
        .ok()
        .and_then(|t| {
            t.lines()
                .rev()
                .find(|l| l.contains("stopped"))
                .map(str::to_string)
        })
        .unwrap_or_default();
    Ok(format!(
        "monitor CPU over the {window:.1} s window (/proc): {:.2} % of one core; getrusage over its \
         whole life ({life:.1} s incl. start-up): user {user:.3} s + sys {sys:.3} s = {:.2} %; \
         per thread over the window: {}; max RSS {} KiB; voluntary/involuntary context switches \
         {}/{}; trips {:?}\n{summary}",
        (cpu1 - cpu0) / window * 100.0,
        (user + sys) / life * 100.0,
        per_thread.join(", "),
        ru.max_rss_kib,
        ru.voluntary_switches,
        ru.involuntary_switches,
        trips
    ))
}
