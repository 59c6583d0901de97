//! Buffers that are resident from the moment they are made.
//!
//! In: a `Vec` allocated at start-up for its worst case (`Vec::with_capacity`, `vec![0; n]`).
//! Out: the same `Vec`, its values unchanged, every page of its allocation (length and spare
//! capacity) written once, so that the operating system has given it memory now.
//!
//! **Why.** Linux hands out a large allocation's pages on first write: a buffer sized at start-up
//! for the most edges a frame can have, but filled only as far as the frames so far reached,
//! takes more memory each time a frame or a search reaches further into it. The search backlog
//! (32 frames of up to 1,536 edges, 12 MB) had each relocalisation's kept frames land in
//! slots not written before: the resident set grew by about 90 KB per relocalisation for the
//! first hundred of them (issue 50), though nothing was allocated. Written at start-up, the
//! process's memory is what it will be for the whole run, the frame path takes no page faults
//! on its buffers, and a device without the memory finds out at start-up, not an hour in.

/// Bytes between two writes: the smallest page size of the targets (a larger page is written
/// more than once, which costs nothing but time at start-up).
const STRIDE: usize = 4096;

/// `v`, with every page of its allocation written once (its values unchanged): see the module
/// doc.
pub fn resident<T>(mut v: Vec<T>) -> Vec<T> {
    let bytes = v.capacity() * std::mem::size_of::<T>();
    let base = v.as_mut_ptr().cast::<std::mem::MaybeUninit<u8>>();
    for offset in (0..bytes).step_by(STRIDE) {
        // SAFETY: `offset` lies inside the allocation of `v`'s capacity, which `v` owns; a byte
        // read as `MaybeUninit` (initialised or not) and written back unchanged alters no value.
        // Volatile, so that the write is neither dropped as a no-op nor turned into a `calloc`
        // by the optimiser, either of which would leave the page untouched.
        unsafe {
            let p = base.add(offset);
            p.write_volatile(p.read_volatile());
        }
    }
    v
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::resident;

    /// Bytes of `v`'s allocation whose pages are in memory (`mincore`).
    fn resident_bytes<T>(v: &Vec<T>) -> usize {
        // SAFETY: sysconf only reads a system constant.
        let page = unsafe { libc::sysconf(libc::_SC_PAGESIZE) } as usize;
        let start = v.as_ptr() as usize & !(page - 1);
        let end = v.as_ptr() as usize + v.capacity() * std::mem::size_of::<T>();
        let pages = (end - start).div_ceil(page);
        let mut flags = vec![0u8; pages];
        // SAFETY: the range is the pages of `v`'s allocation, mapped while `v` lives; `flags`
        // has one byte per page.
        let r = unsafe { libc::mincore(start as *mut libc::c_void, pages * page, flags.as_mut_ptr()) };
        assert_eq!(r, 0, "mincore");
        flags.iter().filter(|f| **f & 1 == 1).count() * page
    }

    /// 64 MB: above the most (32 MB) that the C allocator's moving threshold serves from its
    /// heap, so each is a fresh mapping whose pages the kernel gives on first write.
    const BYTES: usize = 64 << 20;

    #[test]
    fn a_buffer_made_resident_is_in_memory_to_its_last_page_and_an_untouched_one_is_not() {
        let untouched: Vec<u64> = Vec::with_capacity(BYTES / 8);
        assert!(
            resident_bytes(&untouched) < BYTES / 16,
            "{}",
            resident_bytes(&untouched)
        );
        let made = resident(Vec::<u64>::with_capacity(BYTES / 8));
        assert!(made.is_empty());
        assert!(resident_bytes(&made) >= BYTES, "{}", resident_bytes(&made));
        let zeroed = vec![0u32; BYTES / 4];
        assert!(resident_bytes(&zeroed) < BYTES / 16, "{}", resident_bytes(&zeroed));
        let zeroed = resident(zeroed);
        assert!(resident_bytes(&zeroed) >= BYTES, "{}", resident_bytes(&zeroed));
        assert!(zeroed.iter().all(|x| *x == 0));
    }

    #[test]
    fn the_values_in_a_buffer_made_resident_are_kept() {
        let v: Vec<u16> = (0..50_000).collect();
        let mut v = resident(v);
        assert!(v.iter().enumerate().all(|(k, x)| usize::from(*x) == k));
        v.push(7);
        assert_eq!(v.len(), 50_001);
        assert!(resident(Vec::<()>::with_capacity(10)).is_empty());
        assert!(resident(Vec::<u8>::new()).is_empty());
    }
}
