//! Software prefetches: hints that ask the cache for memory a loop will read soon, so that the
//! read does not wait on main memory. The per-step metric and fusion loops walk blocks of
//! clouds of ~30 MB in an order the hardware prefetcher cannot guess (the next block's data is
//! elsewhere); asking for it one block ahead took the fusion of a view from 3.35 to 2.28 ms
//! (`fusion_views`). A prefetch never changes a result: it reads nothing into the program.

/// Asks for the cache lines at `data`'s first byte and every 64 bytes after it, within `data`:
/// all of its lines but, when it starts mid-line, possibly the last. (Asking for that one too,
/// from the aligned start, made `fusion_views` slower: 2.11–2.25 → 2.37–2.48 ms per view,
/// alternating runs.)
#[inline(always)]
pub(crate) fn range<T>(data: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        let start = data.as_ptr() as *const i8;
        let bytes = std::mem::size_of_val(data);
        let mut off = 0;
        while off < bytes {
            // SAFETY: a prefetch is a hint; the address is within `data`.
            unsafe { std::arch::x86_64::_mm_prefetch(start.add(off), std::arch::x86_64::_MM_HINT_T0) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = data;
}

/// Asks for the line(s) of `item` (both when it straddles two).
#[inline(always)]
pub(crate) fn item<T>(item: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        let start = item as *const T as *const i8;
        // SAFETY: prefetches are hints; both addresses are within `item`.
        unsafe {
            std::arch::x86_64::_mm_prefetch(start, std::arch::x86_64::_MM_HINT_T0);
            std::arch::x86_64::_mm_prefetch(
                start.add(std::mem::size_of::<T>().saturating_sub(1)),
                std::arch::x86_64::_MM_HINT_T0,
            );
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = item;
}
