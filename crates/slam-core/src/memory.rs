//! How much memory a command may still take, so that work whose size the user chooses (a generated
//! problem, a network input, a decoded image) is refused with the figure it needs instead of aborting
//! half-way when an allocation fails.

/// Memory this process may still allocate, bytes: the smaller of the machine's available memory
/// (`MemAvailable` of `/proc/meminfo`: free memory plus what the kernel can reclaim) and what the
/// process's address-space limit (`ulimit -v`, `RLIMIT_AS`) leaves above its current virtual size.
/// `None` where neither can be read (no `/proc`): the caller then does not refuse.
pub fn available_bytes() -> Option<u64> {
    let machine = std::fs::read_to_string("/proc/meminfo").ok().and_then(|t| kib_field(&t, "MemAvailable"));
    let limit = std::fs::read_to_string("/proc/self/limits").ok().and_then(|t| address_space_limit(&t));
    let used = std::fs::read_to_string("/proc/self/status").ok().and_then(|t| kib_field(&t, "VmSize"));
    let under_limit = limit.map(|l| l.saturating_sub(used.unwrap_or(0)));
    match (machine, under_limit) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// A `kB` line of `/proc/meminfo` or `/proc/self/status` (`MemAvailable:  123 kB`), in bytes.
fn kib_field(text: &str, key: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let rest = l.strip_prefix(key)?.strip_prefix(':')?;
        rest.split_whitespace().next()?.parse::<u64>().ok().map(|k| k * 1024)
    })
}

/// The soft address-space limit of `/proc/self/limits` (`Max address space  unlimited  unlimited  bytes`),
/// `None` when unlimited.
fn address_space_limit(text: &str) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with("Max address space"))?;
    line["Max address space".len()..].split_whitespace().next()?.parse().ok()
}

/// A byte count as people read it: `2.9 TB`, `7.2 GB`, `350 MB` (decimal units, as `free -h` does not,
/// but as disk and memory vendors do; one decimal from GB on).
pub fn human_bytes(bytes: f64) -> String {
    const UNITS: [(&str, f64); 4] = [("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)];
    for (unit, size) in UNITS {
        if bytes >= size {
            return if size >= 1e9 {
                format!("{:.1} {unit}", bytes / size)
            } else {
                format!("{:.0} {unit}", bytes / size)
            };
        }
    }
    format!("{bytes:.0} bytes")
}

/// Refuse work that needs `need` bytes when this process cannot have them: the message gives both
/// figures and what the work is (`what`, e.g. "the dense reduced matrix of 600000 unknowns").
pub fn check_fits(what: &str, need: f64) -> Result<(), String> {
    match available_bytes() {
        Some(have) if need > have as f64 => Err(format!(
            "{what} needs about {} of memory; this process can have {} (the machine's available memory, or its \
             ulimit -v, whichever is less)",
            human_bytes(need),
            human_bytes(have as f64)
        )),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn proc_files_are_read_and_figures_printed_in_units() {
        let meminfo = "MemTotal:       24000000 kB\nMemAvailable:   22000000 kB\n";
        assert_eq!(kib_field(meminfo, "MemAvailable"), Some(22_000_000 * 1024));
        assert_eq!(kib_field(meminfo, "VmSize"), None);
        let limits = "Limit                     Soft Limit           Hard Limit           Units\n\
                      Max address space         8192000000           unlimited            bytes\n";
        assert_eq!(address_space_limit(limits), Some(8_192_000_000));
        let unlimited = "Max address space         unlimited            unlimited            bytes\n";
        assert_eq!(address_space_limit(unlimited), None);
        assert_eq!(human_bytes(2.88e12), "2.9 TB");
        assert_eq!(human_bytes(3.5e8), "350 MB");
        assert_eq!(human_bytes(12.0), "12 bytes");
        // on this machine something is available, and an exabyte is not
        assert!(available_bytes().is_some_and(|b| b > 0));
        let e = check_fits("a test allocation", 1e18).expect_err("an exabyte");
        assert!(e.starts_with("a test allocation needs about 1000000.0 TB"), "{e}");
        check_fits("a kilobyte", 1e3).expect("fits");
    }
}
