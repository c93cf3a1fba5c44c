//! The hand-over from zenoh's threads to the stage's thread: a bounded crossbeam channel
//! that keeps the newest samples. When it is full the sender takes the oldest out and counts
//! it, so a slow stage sees fresh data and a burst never grows memory.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use crossbeam_channel::{Receiver, Sender, TrySendError};

/// The sending side (cloned into zenoh's callback).
#[derive(Debug)]
pub struct NewestSender<T> {
    tx: Sender<T>,
    rx: Receiver<T>,
    dropped: Arc<AtomicU64>,
}

impl<T> Clone for NewestSender<T> {
    fn clone(&self) -> Self {
        Self {
            tx: self.tx.clone(),
            rx: self.rx.clone(),
            dropped: Arc::clone(&self.dropped),
        }
    }
}

/// The receiving side (the stage's thread).
#[derive(Debug)]
pub struct NewestReceiver<T> {
    rx: Receiver<T>,
    dropped: Arc<AtomicU64>,
}

/// A channel holding at most `capacity` (at least 1) items, dropping the oldest when full.
pub fn newest<T>(capacity: usize) -> (NewestSender<T>, NewestReceiver<T>) {
    let (tx, rx) = crossbeam_channel::bounded(capacity.max(1));
    let dropped = Arc::new(AtomicU64::new(0));
    (
        NewestSender {
            tx,
            rx: rx.clone(),
            dropped: Arc::clone(&dropped),
        },
        NewestReceiver { rx, dropped },
    )
}

impl<T> NewestSender<T> {
    /// Queues `item`, dropping (and counting) the oldest items while the queue is full.
    /// Returns false when the receiver is gone.
    pub fn push(&self, mut item: T) -> bool {
        loop {
            match self.tx.try_send(item) {
                Ok(()) => return true,
                Err(TrySendError::Disconnected(_)) => return false,
                Err(TrySendError::Full(back)) => {
                    item = back;
                    if self.rx.try_recv().is_ok() {
                        self.dropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        }
    }
}

impl<T> NewestReceiver<T> {
    /// The next item, if one is queued.
    pub fn try_pop(&self) -> Option<T> {
        self.rx.try_recv().ok()
    }

    /// Items dropped because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_queue_keeps_the_newest_and_counts_the_rest() {
        let (tx, rx) = newest(3);
        for i in 0..10 {
            assert!(tx.push(i));
        }
        assert_eq!(rx.dropped(), 7);
        let got: Vec<i32> = std::iter::from_fn(|| rx.try_pop()).collect();
        assert_eq!(got, vec![7, 8, 9]);
    }

    #[test]
    fn concurrent_senders_never_exceed_the_capacity() {
        let (tx, rx) = newest(4);
        let threads: Vec<_> = (0..4)
            .map(|t| {
                let tx = tx.clone();
                std::thread::spawn(move || {
                    for i in 0..1000 {
                        tx.push(t * 1000 + i);
                    }
                })
            })
            .collect();
        for t in threads {
            t.join().expect("sender thread");
        }
        let left = std::iter::from_fn(|| rx.try_pop()).count() as u64;
        assert!(left <= 4);
        assert_eq!(left + rx.dropped(), 4000);
    }
}
