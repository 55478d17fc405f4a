//! Large read-mostly arrays on 2 MiB pages where the OS offers them.
//!
//! The tracer's tree and leaves and the scene's triangles are read at
//! scattered places, tens of megabytes apart: with 4 KiB pages nearly every
//! triangle a raster bin names, and many a node or leaf the tracer pops,
//! also misses the TLB. Embree allocates its BVH on huge pages on Linux by
//! default (`rtcNewDevice`'s `hugepages` option), so the peers bench must give
//! the core the same, or it measures page walks. On Linux, [`with_capacity`]
//! marks a large allocation `MADV_HUGEPAGE` before its pages are first
//! touched, so that transparent huge pages back it wherever the kernel has
//! them ("madvise" or "always" mode); elsewhere, or when the kernel refuses,
//! it is an ordinary allocation. Nothing observable but time changes.

/// Below this size an array is left alone (it spans few pages anyway).
const MIN_BYTES: usize = 4 << 20;

/// A 2 MiB huge page.
#[cfg(target_os = "linux")]
const HUGE: usize = 2 << 20;

/// An empty vector with room for `n` elements, its allocation advised to
/// use huge pages when it is large (so fill it after this call: pages
/// touched before the advice stay small).
pub(crate) fn with_capacity<T>(n: usize) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n);
    let bytes = n.saturating_mul(std::mem::size_of::<T>());
    if bytes >= MIN_BYTES {
        advise(v.as_mut_ptr().cast(), bytes);
    }
    v
}

/// Marks the whole 2 MiB pages inside `[ptr, ptr + bytes)` `MADV_HUGEPAGE`
/// (a hint: an error leaves the pages as they were).
#[cfg(target_os = "linux")]
fn advise(ptr: *mut u8, bytes: usize) {
    let start = (ptr as usize).next_multiple_of(HUGE);
    let end = (ptr as usize + bytes) / HUGE * HUGE;
    if end > start {
        // SAFETY: the range lies inside an allocation this process owns
        // (`advised`'s fresh vector, `bytes` long), and MADV_HUGEPAGE only
        // changes how its pages are backed, never their contents.
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_ptr: *mut u8, _bytes: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    /// An advised vector is an ordinary one: empty, with the room asked
    /// for, and it keeps what is written to it, large or small.
    #[test]
    fn advised_vectors_are_vectors() {
        for n in [0usize, 10, (MIN_BYTES / 8) + 12345] {
            let mut v: Vec<u64> = with_capacity(n);
            assert!(v.is_empty() && v.capacity() >= n);
            v.extend((0..n as u64).map(|i| i.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
            assert!((0..n).all(|i| v[i] == (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)));
        }
    }
}
