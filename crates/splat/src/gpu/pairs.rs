//! How many (tile, Gaussian) pair slots a render allocates, and when the number of pairs it
//! needed comes back to the host.
//!
//! The number of pairs is known only once the tile counts are scanned on the device. Reading it
//! there stalls the render halfway: the host waits for the device to drain, then launches the
//! rest. A render made inside [`deferred`] does not wait: it allocates a *capacity* guessed from
//! the renders before it on this thread (a quarter above the most pairs one needed), leaves the
//! count on the device, and, when its pairs did not fit, fills its image with NaN. Its caller's
//! next read-back (a trainer reads its loss every iteration) then sees a value that is not
//! finite, and [`PairCountCheck::overflowed`] says whether that is the reason, raising the guess
//! so that the render made again fits. Every other render reads its count at once and sizes its
//! buffers exactly.

use std::cell::RefCell;

use cubecl::prelude::*;
use cubecl::server::Handle;

use super::launch::read_u32_at;

thread_local! {
    static BUDGET: RefCell<Budget> = RefCell::new(Budget::default());
}

/// This thread's pair-slot policy.
#[derive(Default)]
struct Budget {
    /// Whether renders leave their pair counts on the device (inside [`deferred`]).
    deferring: bool,
    /// Slots a deferred render allocates; 0 until a render's count has been read.
    capacity: usize,
    /// Deferred renders whose counts nobody has read.
    pending: Vec<Pending>,
}

/// A deferred render's pair count, on the device, and the slots it had.
pub(super) struct Pending {
    pub client: Client,
    /// One `u32`: the number of pairs the render needed.
    pub total: Handle,
    pub capacity: usize,
}

/// The slots for `pairs` pairs and a quarter more, so that views with a few more pairs than the
/// last and a slowly growing model fit without another read.
fn with_headroom(pairs: usize) -> usize {
    pairs + pairs / 4 + 1
}

/// Runs `render` with the renders it makes on this thread leaving their pair counts on the
/// device; returns its result and the check of those renders.
pub fn deferred<R>(render: impl FnOnce() -> R) -> (R, PairCountCheck) {
    struct Restore {
        was_deferring: bool,
        first_pending: usize,
    }
    impl Drop for Restore {
        fn drop(&mut self) {
            BUDGET.with_borrow_mut(|b| {
                b.deferring = self.was_deferring;
                b.pending.truncate(self.first_pending);
            });
        }
    }
    let restore = BUDGET.with_borrow_mut(|b| Restore {
        was_deferring: std::mem::replace(&mut b.deferring, true),
        first_pending: b.pending.len(),
    });
    let out = render();
    let pending = BUDGET.with_borrow_mut(|b| b.pending.split_off(restore.first_pending));
    drop(restore);
    (out, PairCountCheck { pending })
}

/// The slots of the next render's pairs: `Some(capacity)` when it is deferred and a guess exists,
/// `None` when it must read its count now.
pub(super) fn capacity() -> Option<usize> {
    BUDGET.with_borrow(|b| (b.deferring && b.capacity > 0).then_some(b.capacity))
}

/// Records that a render needed `pairs` slots.
pub(super) fn needed(pairs: usize) {
    BUDGET.with_borrow_mut(|b| b.capacity = b.capacity.max(with_headroom(pairs)));
}

/// Keeps a deferred render's count for its [`PairCountCheck`].
pub(super) fn leave(pending: Pending) {
    BUDGET.with_borrow_mut(|b| b.pending.push(pending));
}

/// Sets this thread's guess (tests force an overflow with it).
#[cfg(test)]
pub(super) fn set_capacity(capacity: usize) {
    BUDGET.with_borrow_mut(|b| b.capacity = capacity);
}

/// The pair counts of the renders made inside one [`deferred`] call, still on the device.
pub struct PairCountCheck {
    pending: Vec<Pending>,
}

impl PairCountCheck {
    /// Whether any of the renders ran out of pair slots (so its image is NaN). Reads each
    /// render's count back, so it is meant for when a read-back already showed a value that is
    /// not finite; raises this thread's guess to fit them.
    pub fn overflowed(&self) -> bool {
        let mut overflowed = false;
        for p in &self.pending {
            let pairs = read_u32_at(&p.client, &p.total, 0) as usize;
            needed(pairs);
            overflowed |= pairs > p.capacity;
        }
        overflowed
    }
}
