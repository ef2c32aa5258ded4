//! The `ArcThreadSafetyPolicy` of vic's iceoryx2 service: iceoryx2's single-threaded policy (a
//! reference-counted box, not `Send`, no lock) whose boxes are recycled instead of freed.
//!
//! Why: iceoryx2 0.10 creates one of these per loaned sample — `Publisher::loan_uninit` (and so
//! `send_copy`) → `SampleMutUninit::new` → `ChunkMutSharedState::new`
//! (port/details/chunk_mut_shared_state.rs:102) → `ArcSyncPolicy::new`, which for the `ipc`
//! service is `Rc::new` (iceoryx2-cal arc_sync_policy/single_threaded.rs:69): one 48-byte heap
//! allocation and one free per publish, on every path that sends. The board publishes its state
//! every tick of its 1 kHz loop, where nothing may allocate. Here a dropped box goes onto a
//! per-thread free list of its size, and the next box of that size is taken from it: after the
//! first publish of a thread, publishing takes no memory from the allocator.

use core::cell::Cell;
use core::fmt::Debug;
use core::marker::PhantomData;
use core::ops::Deref;
use core::ptr::NonNull;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_cal::arc_sync_policy::{ArcSyncPolicy, ArcSyncPolicyCreationError, LockGuard};
use std::alloc::{Layout, alloc, dealloc};

/// Box sizes a thread keeps free lists for; boxes of other sizes are freed as usual.
const SIZES: usize = 8;
/// Free boxes kept per size: a burst of loans does not hoard memory beyond this.
const KEPT: usize = 64;

/// A reference-counted box of `T` whose memory is recycled per thread (see the module doc).
pub struct Recycled<T: Send + Debug + Abandonable> {
    inner: NonNull<Inner<T>>,
    /// Like `Rc`: neither `Send` nor `Sync` (the count is a plain cell).
    _not_send: PhantomData<*const Inner<T>>,
}

struct Inner<T> {
    refs: Cell<usize>,
    value: T,
}

/// Access to the value; there is no lock (one thread).
pub struct Guard<'a, T> {
    value: &'a T,
}

impl<T> Deref for Guard<'_, T> {
    type Target = T;
    fn deref(&self) -> &T {
        self.value
    }
}

impl<'a, T: Send + Abandonable> LockGuard<'a, T> for Guard<'a, T> {}

impl<T: Send + Debug + Abandonable> Recycled<T> {
    fn inner(&self) -> &Inner<T> {
        // SAFETY: the box lives while any `Recycled` pointing to it does (the count).
        unsafe { self.inner.as_ref() }
    }
}

impl<T: Send + Debug + Abandonable> ArcSyncPolicy<T> for Recycled<T> {
    type LockGuard<'parent>
        = Guard<'parent, T>
    where
        Self: 'parent,
        T: 'parent;

    fn new(value: T) -> Result<Self, ArcSyncPolicyCreationError> {
        let layout = Layout::new::<Inner<T>>();
        let ptr = match take(layout) {
            Some(p) => p,
            // SAFETY: `Inner` holds a `usize`, so the layout is not zero-sized.
            None => unsafe { alloc(layout) },
        };
        let Some(ptr) = NonNull::new(ptr.cast::<Inner<T>>()) else {
            return Err(ArcSyncPolicyCreationError::InsufficientResources);
        };
        let inner = Inner {
            refs: Cell::new(1),
            value,
        };
        // SAFETY: `ptr` is a fresh (or recycled, unused) block of `Inner<T>`'s layout.
        unsafe { ptr.as_ptr().write(inner) };
        Ok(Recycled {
            inner: ptr,
            _not_send: PhantomData,
        })
    }

    fn lock(&self) -> Guard<'_, T> {
        Guard {
            value: &self.inner().value,
        }
    }
}

impl<T: Send + Debug + Abandonable> Clone for Recycled<T> {
    fn clone(&self) -> Self {
        let refs = &self.inner().refs;
        refs.set(refs.get() + 1);
        Recycled {
            inner: self.inner,
            _not_send: PhantomData,
        }
    }
}

impl<T: Send + Debug + Abandonable> Drop for Recycled<T> {
    fn drop(&mut self) {
        let refs = &self.inner().refs;
        refs.set(refs.get() - 1);
        if refs.get() > 0 {
            return;
        }
        let ptr = self.inner.as_ptr();
        // SAFETY: the last reference: the value is dropped once, then its block is reused or
        // freed with the layout it was allocated with.
        unsafe {
            core::ptr::drop_in_place(ptr);
            let layout = Layout::new::<Inner<T>>();
            if !give(layout, ptr.cast()) {
                dealloc(ptr.cast(), layout);
            }
        }
    }
}

impl<T: Send + Debug + Abandonable> Abandonable for Recycled<T> {
    /// As iceoryx2's single-threaded policy: the last reference abandons the value (and leaks
    /// its block), any other is dropped.
    unsafe fn abandon_in_place(mut this: NonNull<Self>) {
        // SAFETY: the caller's contract; `this` is valid and not used afterwards.
        unsafe {
            let this = this.as_mut();
            if this.inner().refs.get() == 1 {
                let value = &raw mut (*this.inner.as_ptr()).value;
                T::abandon_in_place(NonNull::new_unchecked(value));
            } else {
                core::ptr::drop_in_place(this);
            }
        }
    }
}

impl<T: Send + Debug + Abandonable> Debug for Recycled<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Recycled")
            .field("value", &self.inner().value)
            .finish()
    }
}

/// One free list: blocks of `layout`, each holding the address of the next in its first word.
struct FreeList {
    layout: Cell<Option<Layout>>,
    head: Cell<*mut u8>,
    len: Cell<usize>,
}

/// This thread's free lists; the blocks go back to the allocator when the thread ends.
struct Pool([FreeList; SIZES]);

impl Drop for Pool {
    fn drop(&mut self) {
        for list in &self.0 {
            let Some(layout) = list.layout.get() else {
                continue;
            };
            let mut p = list.head.replace(core::ptr::null_mut());
            while !p.is_null() {
                // SAFETY: every block on the list was allocated with `layout` and holds the next.
                unsafe {
                    let next = p.cast::<*mut u8>().read();
                    dealloc(p, layout);
                    p = next;
                }
            }
        }
    }
}

thread_local! {
    static POOL: Pool = const {
        Pool([const {
            FreeList {
                layout: Cell::new(None),
                head: Cell::new(core::ptr::null_mut()),
                len: Cell::new(0),
            }
        }; SIZES])
    };
}

/// A free block of `layout` from this thread's pool, if there is one.
fn take(layout: Layout) -> Option<*mut u8> {
    POOL.try_with(|pool| {
        let list = pool.0.iter().find(|l| l.layout.get() == Some(layout))?;
        let p = list.head.get();
        if p.is_null() {
            return None;
        }
        // SAFETY: a block on the list holds the address of the next one.
        list.head.set(unsafe { p.cast::<*mut u8>().read() });
        list.len.set(list.len.get() - 1);
        Some(p)
    })
    .ok()
    .flatten()
}

/// Puts the block `p` of `layout` on this thread's pool; false if it is to be freed instead
/// (pool full, or the thread ending).
fn give(layout: Layout, p: *mut u8) -> bool {
    // The block must hold the link to the next one.
    if layout.size() < size_of::<*mut u8>() || layout.align() < align_of::<*mut u8>() {
        return false;
    }
    POOL.try_with(|pool| {
        let list = pool
            .0
            .iter()
            .find(|l| l.layout.get() == Some(layout))
            .or_else(|| pool.0.iter().find(|l| l.layout.get().is_none()));
        let Some(list) = list else { return false };
        if list.len.get() >= KEPT {
            return false;
        }
        list.layout.set(Some(layout));
        // SAFETY: the block is unused, large and aligned enough for the link.
        unsafe { p.cast::<*mut u8>().write(list.head.get()) };
        list.head.set(p);
        list.len.set(list.len.get() + 1);
        true
    })
    .unwrap_or(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::rc::Rc;

    /// Counts its drops; abandoning it does not.
    #[derive(Debug)]
    struct Counted(Rc<Cell<u32>>);

    impl Drop for Counted {
        fn drop(&mut self) {
            self.0.set(self.0.get() + 1);
        }
    }

    impl Abandonable for Counted {
        unsafe fn abandon_in_place(this: NonNull<Self>) {
            // SAFETY: the caller's contract; the Rc inside is released, the count not touched.
            unsafe { core::ptr::drop_in_place(&raw mut (*this.as_ptr()).0) };
        }
    }

    // SAFETY: used on one thread only.
    unsafe impl Send for Counted {}

    #[test]
    fn the_value_is_dropped_once_by_the_last_reference_and_its_block_reused() {
        let drops = Rc::new(Cell::new(0));
        let a = Recycled::new(Counted(drops.clone())).unwrap();
        let first = a.inner.as_ptr() as usize;
        let b = a.clone();
        assert!(Rc::ptr_eq(&a.lock().0, &b.lock().0));
        drop(a);
        assert_eq!(drops.get(), 0, "dropped while a reference remained");
        drop(b);
        assert_eq!(drops.get(), 1);
        // The next box of that size is the recycled one.
        let c = Recycled::new(Counted(drops.clone())).unwrap();
        assert_eq!(c.inner.as_ptr() as usize, first, "the block was not reused");
        // Abandoning the last reference releases the value without dropping it.
        let mut c = core::mem::ManuallyDrop::new(c);
        // SAFETY: `c` is valid and never used (nor dropped) afterwards.
        unsafe { Recycled::abandon_in_place(NonNull::from_mut(&mut *c)) };
        assert_eq!(drops.get(), 1);
        assert_eq!(
            Rc::strong_count(&drops),
            1,
            "the abandoned value kept its Rc"
        );
    }
}
