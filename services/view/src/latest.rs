//! A channel that keeps only the newest value: the receive thread hands work to the encoder
//! without ever waiting, and an encoder that falls behind skips to the newest frame instead
//! of working through a queue of old ones.

use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};

/// The sending side of [`latest`].
#[derive(Debug)]
pub struct LatestSender<T> {
    tx: Sender<T>,
    // Kept to take the stale value out when the slot is full.
    rx: Receiver<T>,
}

/// A one-slot channel whose sender replaces an unread value.
pub fn latest<T>() -> (LatestSender<T>, Receiver<T>) {
    let (tx, rx) = bounded(1);
    (LatestSender { tx, rx: rx.clone() }, rx)
}

impl<T> LatestSender<T> {
    /// Puts `value` in the slot; returns whether it replaced one that was never read. It
    /// never blocks, and never fails: the sender holds a receiver of its own, so the channel
    /// stays open (whether the encoder thread still runs is its join handle's business).
    pub fn send(&self, mut value: T) -> bool {
        let mut replaced = false;
        loop {
            match self.tx.try_send(value) {
                Ok(()) => return replaced,
                Err(TrySendError::Full(v)) => {
                    value = v;
                    replaced |= self.rx.try_recv().is_ok();
                }
                Err(TrySendError::Disconnected(_)) => return replaced,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_only_the_newest() {
        let (tx, rx) = latest();
        assert!(!tx.send(1));
        assert!(tx.send(2));
        assert!(tx.send(3));
        assert_eq!(rx.try_recv().ok(), Some(3));
        assert!(rx.try_recv().is_err());
        assert!(!tx.send(4));
    }
}
