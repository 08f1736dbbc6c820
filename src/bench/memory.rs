//! Peak resident memory of a job (Linux `/proc`): the bench's maps jobs report it beside their
//! seconds, since at 1024^2 memory, not time, decides whether a fit runs on a laptop.
//!
//! | call | reads or writes |
//! | --- | --- |
//! | [`reset_peak`] | writes `5` to `/proc/self/clear_refs`, which sets the peak (`VmHWM`) to the present resident size (Linux 4.0 and later) |
//! | [`peak_resident_bytes`] | `VmHWM` of `/proc/self/status` |
//!
//! Elsewhere both do nothing and the peak is `None`.

use std::fs;

/// Starts a new peak at the present resident size; `false` where the system cannot.
pub fn reset_peak() -> bool {
    fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The largest resident size of this process since it started or since [`reset_peak`], in
/// bytes.
pub fn peak_resident_bytes() -> Option<u64> {
    let status = fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kilobytes: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kilobytes * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Touching 256 MB more than is resident raises the peak by about that much, and a reset
    /// after freeing it brings the peak back down below it.
    #[test]
    fn the_peak_follows_memory_touched_and_resets() {
        if !reset_peak() {
            return; // not Linux, or /proc not writable: nothing to measure
        }
        let before = peak_resident_bytes().expect("VmHWM beside clear_refs");
        let size = 256 << 20;
        let block = std::hint::black_box(vec![1u8; size]);
        let during = peak_resident_bytes().unwrap();
        assert!(
            during >= before + size as u64 * 9 / 10,
            "{before} -> {during}"
        );
        drop(block);
        assert!(reset_peak());
        let after = peak_resident_bytes().unwrap();
        assert!(after < during - size as u64 / 2, "{during} -> {after}");
    }
}
