//! The in-process transport: one thread per rank, unbounded channels between them.

use super::exec::{Transport, TransportError};
use std::collections::VecDeque;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::vec::Vec;

type Envelope = (u32, u32, Vec<u8>); // from, tag, bytes

/// One rank of an in-process group. Sends never block, so [`Transport::exchange`] cannot
/// deadlock; messages that arrive early (from a later round) wait in a buffer.
///
/// ```
/// use strahl::composite::{ThreadTransport, Transport};
/// let sums = ThreadTransport::run(4, |t| {
///     let next = (t.rank() + 1) % 4;
///     let prev = (t.rank() + 3) % 4;
///     let got = t.exchange(0, vec![(next, vec![t.rank() as u8])], &[prev]).unwrap();
///     got[0][0]
/// });
/// assert_eq!(sums, [3, 0, 1, 2]);
/// ```
pub struct ThreadTransport {
    rank: u32,
    peers: Vec<Sender<Envelope>>,
    inbox: Receiver<Envelope>,
    early: VecDeque<Envelope>,
    /// Bytes handed to `exchange` for sending, summed.
    pub bytes_sent: u64,
    /// How long a receive waits before it reports an error (a peer that panicked or never sends);
    /// 60 s by default. Every rank holds a sender to every other, so a lost peer shows only so.
    pub timeout: std::time::Duration,
}

impl ThreadTransport {
    /// `p` connected ranks (at least one).
    ///
    /// ```
    /// use strahl::composite::{ThreadTransport, Transport};
    /// let mut g = ThreadTransport::group(2);
    /// g[0].exchange(0, vec![(1, b"hi".to_vec())], &[]).unwrap(); // sends never block
    /// let got = g[1].exchange(0, vec![], &[0]).unwrap();
    /// assert_eq!(got, [b"hi".to_vec()]);
    /// assert_eq!(ThreadTransport::group(0).len(), 1); // at least one rank
    /// ```
    pub fn group(p: u32) -> Vec<Self> {
        let p = p.max(1);
        let (txs, rxs): (Vec<_>, Vec<_>) = (0..p).map(|_| channel()).unzip();
        rxs.into_iter()
            .enumerate()
            .map(|(r, inbox)| Self {
                rank: r as u32,
                peers: txs.clone(),
                inbox,
                early: VecDeque::new(),
                bytes_sent: 0,
                timeout: std::time::Duration::from_secs(60),
            })
            .collect()
    }

    /// Runs `f` on `p` threads, one per rank, and returns the results in rank order. A panic in
    /// one rank is propagated after the others end (their transports then report errors).
    ///
    /// ```
    /// use strahl::composite::{ThreadTransport, Transport};
    /// let squares = ThreadTransport::run(4, |t| t.rank() * t.rank());
    /// assert_eq!(squares, [0, 1, 4, 9]); // in rank order
    /// ```
    pub fn run<R: Send, F: Fn(&mut ThreadTransport) -> R + Sync>(p: u32, f: F) -> Vec<R> {
        let group = Self::group(p);
        std::thread::scope(|s| {
            let handles: Vec<_> = group
                .into_iter()
                .map(|mut t| {
                    let f = &f;
                    s.spawn(move || f(&mut t))
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        })
    }
}

impl Transport for ThreadTransport {
    fn rank(&self) -> u32 {
        self.rank
    }

    fn size(&self) -> u32 {
        self.peers.len() as u32
    }

    fn exchange(&mut self, tag: u32, sends: Vec<(u32, Vec<u8>)>, from: &[u32]) -> Result<Vec<Vec<u8>>, TransportError> {
        for (to, bytes) in sends {
            self.bytes_sent += bytes.len() as u64;
            let peer = self.peers.get(to as usize).ok_or(TransportError("no such rank"))?;
            peer.send((self.rank, tag, bytes))
                .map_err(|_| TransportError("peer hung up"))?;
        }
        // A rank outside the group never sends: an error now, not a wait for the timeout.
        if from.iter().any(|&src| src as usize >= self.peers.len()) {
            return Err(TransportError("no such rank"));
        }
        let mut out = Vec::with_capacity(from.len());
        for &src in from {
            if let Some(i) = self.early.iter().position(|(f, t, _)| *f == src && *t == tag) {
                out.push(self.early.remove(i).map(|e| e.2).unwrap_or_default());
                continue;
            }
            loop {
                let env = self
                    .inbox
                    .recv_timeout(self.timeout)
                    .map_err(|_| TransportError("receive timed out"))?;
                if env.0 == src && env.1 == tag {
                    out.push(env.2);
                    break;
                }
                self.early.push_back(env);
            }
        }
        Ok(out)
    }
}
