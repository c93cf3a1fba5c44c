//! CPU time and resident memory of a process, from `/proc` (Linux): what `hvs bench
//! pipeline` and the soak report per stage. Written by hand: two short text files, where a
//! crate such as `procfs` would bring a large dependency for two numbers.

/// One reading of a process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProcSample {
    /// User plus system CPU time so far, seconds.
    pub cpu_s: f64,
    /// Resident set size, bytes.
    pub rss_bytes: u64,
}

/// Reads `/proc/<pid>/stat` and `/proc/<pid>/statm`; `None` when the process is gone.
pub fn sample(pid: u32) -> Option<ProcSample> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let statm = std::fs::read_to_string(format!("/proc/{pid}/statm")).ok()?;
    parse(&stat, &statm, clock_ticks_per_s(), page_bytes())
}

fn parse(stat: &str, statm: &str, ticks_per_s: f64, page_bytes: u64) -> Option<ProcSample> {
    // The command name (field 2) may hold spaces and parentheses: fields count from the last ')'.
    let after = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = after.split_whitespace().collect();
    // After the name: state is field 3, utime field 14, stime field 15.
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    let resident_pages: u64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(ProcSample {
        cpu_s: (utime + stime) as f64 / ticks_per_s,
        rss_bytes: resident_pages * page_bytes,
    })
}

/// Nanoseconds the process's main thread has spent runnable but waiting for a CPU
/// (`/proc/<pid>/schedstat`, second field); `None` when the process is gone or the kernel
/// keeps no such count. A stage's heartbeats come from its main thread.
pub fn run_queue_wait_ns(pid: u32) -> Option<u64> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/schedstat")).ok()?;
    parse_schedstat(&text)
}

fn parse_schedstat(text: &str) -> Option<u64> {
    text.split_whitespace().nth(1)?.parse().ok()
}

/// Bytes as MiB.
pub fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0)
}

fn clock_ticks_per_s() -> f64 {
    // SAFETY: sysconf has no preconditions.
    let t = unsafe { libc::sysconf(libc::_SC_CLK_TCK) };
    if t > 0 { t as f64 } else { 100.0 }
}

fn page_bytes() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let p = unsafe { libc::sysconf(libc::_SC_PAGESIZE) };
    if p > 0 { p as u64 } else { 4096 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_run_queue_wait_is_the_second_schedstat_field() {
        assert_eq!(
            parse_schedstat("166151231 19424771 368\n"),
            Some(19_424_771)
        );
        assert_eq!(parse_schedstat("12"), None);
        assert_eq!(parse_schedstat(""), None);
        // This process exists and has a count (the kernel keeps it here).
        assert!(run_queue_wait_ns(std::process::id()).is_some());
        assert_eq!(run_queue_wait_ns(u32::MAX), None);
    }

    #[test]
    fn fields_count_from_the_last_parenthesis() {
        let stat = "4242 (hvs (x) y) S 1 2 3 4 5 6 7 8 9 10 250 50 0 0 20 0 1 0 100 0 0";
        let s = parse(stat, "1000 300 20 1 0 100 0", 100.0, 4096).expect("parse");
        assert_eq!(s.cpu_s, 3.0);
        assert_eq!(s.rss_bytes, 300 * 4096);
        assert!(parse("garbage", "1 2", 100.0, 4096).is_none());
    }

    #[test]
    fn this_process_has_cpu_time_and_memory() {
        let mut x = 0u64;
        for i in 0..5_000_000u64 {
            x = x.wrapping_add(i * i);
        }
        assert!(x > 0);
        let s = sample(std::process::id()).expect("own /proc entry");
        assert!(s.rss_bytes > 1 << 20, "{s:?}");
        assert!(sample(u32::MAX).is_none());
    }
}
