//! How both FFIs hand what the engine published to the app: Kotlin and Swift listeners
//! ([`super::uniffi`]) and the C position callback ([`super::c`]).
//!
//! Events are queued under the engine's lock, so in the order of the epochs, and delivered
//! after it is released, by one thread at a time: a thread that finds another delivering leaves
//! its events to that one, which delivers until the queue is empty. So two threads' epochs
//! cannot reach the app in the wrong order, nor the app from two threads at once, and a
//! callback that calls the engine does not recurse: what its call publishes is delivered after
//! the current event, by the same thread.

use std::collections::VecDeque;
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::thread::{self, ThreadId};

/// Locks `mutex`, even if a panic elsewhere poisoned it: nothing behind the FFI's locks is left
/// half-changed by a panic (an epoch that panics is undone by the engine, and the queue below
/// changes in single steps).
pub(crate) fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Events waiting for delivery, oldest first, and who is delivering them.
pub(crate) struct Delivery<E> {
    state: Mutex<State<E>>,
}

struct State<E> {
    /// Published by a call still running (see [`Delivery::stage`]).
    staged: Vec<E>,
    /// Ready for delivery, oldest first.
    events: VecDeque<E>,
    /// The thread delivering, if one is.
    deliverer: Option<ThreadId>,
}

impl<E> Delivery<E> {
    pub(crate) fn new() -> Self {
        Self { state: Mutex::new(State { staged: Vec::new(), events: VecDeque::new(), deliverer: None }) }
    }

    /// Holds `event` back until [`commit`](Self::commit), or drops it at
    /// [`discard`](Self::discard): for what the engine publishes during a call, which must not
    /// reach the app if the call panics (the engine undoes the epoch). Call under the engine's
    /// lock, as `commit` and `discard`.
    pub(crate) fn stage(&self, event: E) {
        lock(&self.state).staged.push(event);
    }

    /// Queues what was staged, in order.
    pub(crate) fn commit(&self) {
        let mut state = lock(&self.state);
        let State { staged, events, .. } = &mut *state;
        events.extend(staged.drain(..));
    }

    /// Drops what was staged.
    pub(crate) fn discard(&self) {
        lock(&self.state).staged.clear();
    }

    /// Queues `event` after everything queued so far.
    pub(crate) fn push(&self, event: E) {
        lock(&self.state).events.push_back(event);
    }

    /// Whether the calling thread is delivering: it is inside a callback.
    pub(crate) fn on_delivering_thread(&self) -> bool {
        lock(&self.state).deliverer == Some(thread::current().id())
    }

    /// Delivers the queue, oldest event first, calling `deliver_one` with no lock held, unless
    /// another thread is delivering (it will deliver these events too). Returns when the queue
    /// is empty: when every call has returned, every event has been delivered.
    pub(crate) fn deliver(&self, mut deliver_one: impl FnMut(E)) {
        {
            let mut state = lock(&self.state);
            if state.deliverer.is_some() || state.events.is_empty() {
                return;
            }
            state.deliverer = Some(thread::current().id());
        }
        // Should `deliver_one` unwind, the next call takes over the delivery.
        struct Delivering<'a, E>(&'a Mutex<State<E>>, bool);
        impl<E> Drop for Delivering<'_, E> {
            fn drop(&mut self) {
                if self.1 {
                    lock(self.0).deliverer = None;
                }
            }
        }
        let mut delivering = Delivering(&self.state, true);
        loop {
            let event = {
                let mut state = lock(&self.state);
                match state.events.pop_front() {
                    Some(event) => event,
                    None => {
                        state.deliverer = None;
                        delivering.1 = false;
                        return;
                    }
                }
            };
            deliver_one(event);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    #[test]
    fn staged_events_wait_for_commit_and_discard_drops_them() {
        let delivery = Delivery::new();
        delivery.stage(1);
        delivery.push(0);
        let mut heard = Vec::new();
        delivery.deliver(|e| heard.push(e));
        assert_eq!(heard, [0]);
        delivery.commit();
        delivery.stage(2);
        delivery.discard();
        delivery.deliver(|e| heard.push(e));
        assert_eq!(heard, [0, 1]);
    }

    #[test]
    fn one_thread_delivers_at_a_time_in_order() {
        let delivery = Arc::new(Delivery::new());
        let inside = Arc::new(AtomicUsize::new(0));
        let heard = Arc::new(Mutex::new(Vec::new()));
        let next = Arc::new(Mutex::new(0u32));
        let threads: Vec<_> = (0..8)
            .map(|_| {
                let (delivery, inside, heard, next) =
                    (Arc::clone(&delivery), Arc::clone(&inside), Arc::clone(&heard), Arc::clone(&next));
                thread::spawn(move || {
                    for _ in 0..200 {
                        // Numbered and queued under one lock, as events are under the engine's.
                        {
                            let mut next = lock(&next);
                            delivery.push(*next);
                            *next += 1;
                        }
                        delivery.deliver(|e| {
                            assert_eq!(inside.fetch_add(1, Ordering::SeqCst), 0, "two deliveries at once");
                            assert!(delivery.on_delivering_thread());
                            lock(&heard).push(e);
                            thread::yield_now();
                            inside.fetch_sub(1, Ordering::SeqCst);
                        });
                        assert!(!delivery.on_delivering_thread());
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().unwrap();
        }
        assert_eq!(*lock(&heard), (0..1600).collect::<Vec<u32>>());
    }
}
