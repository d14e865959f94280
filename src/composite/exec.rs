//! The compositing executor, generic over a [`Transport`]: runs a radix-k or tree schedule on one
//! rank's full-size partial image and gathers the result on a root rank.

use super::pixel::Pixel;
use super::schedule::{KVec, RadixK, tree_partner, tree_rounds};
use super::sparse::{DecodeError, decode_composite, encode};
use alloc::vec;
use alloc::vec::Vec;

/// Moves bytes between ranks. Implementations: [`ThreadTransport`](super::ThreadTransport)
/// (in-process, for tests) and, behind the feature `mpi`, `MpiTransport`.
///
/// ```
/// use strahl::composite::{KVec, Plan, RgbaF32, Schedule, Transport, TransportError, composite};
/// struct Solo; // one rank alone: nothing to send or receive
/// impl Transport for Solo {
///     fn rank(&self) -> u32 { 0 }
///     fn size(&self) -> u32 { 1 }
///     fn exchange(&mut self, _: u32, out: Vec<(u32, Vec<u8>)>, from: &[u32]) -> Result<Vec<Vec<u8>>, TransportError> {
///         if out.is_empty() && from.is_empty() { Ok(Vec::new()) } else { Err(TransportError("no such rank")) }
///     }
/// }
/// let img = [RgbaF32([0.5; 4]); 3];
/// let plan = Plan { schedule: Schedule::RadixK(KVec::direct_send(1)), order: &[0], root: 0, sparse: true };
/// assert_eq!(composite(&mut Solo, &img, &plan).unwrap().0.unwrap(), img);
/// ```
pub trait Transport {
    /// This rank, `0 .. size`.
    ///
    /// ```
    /// use strahl::composite::{ThreadTransport, Transport};
    /// assert_eq!(ThreadTransport::run(3, |t| t.rank()), [0, 1, 2]);
    /// ```
    fn rank(&self) -> u32;
    /// Number of ranks.
    ///
    /// ```
    /// use strahl::composite::{ThreadTransport, Transport};
    /// assert_eq!(ThreadTransport::run(3, |t| t.size()), [3, 3, 3]);
    /// ```
    fn size(&self) -> u32;
    /// Sends every `(to, bytes)` of `sends` and returns one message from each rank of `from`, in
    /// that order, all with `tag`. When every rank calls it with matching lists it must not
    /// deadlock (send without blocking, or post the receives first).
    ///
    /// ```
    /// use strahl::composite::{ThreadTransport, Transport};
    /// // Ranks 1 and 2 send to rank 0, which receives in the order it asks for.
    /// let got = ThreadTransport::run(3, |t| {
    ///     let sends = if t.rank() == 0 { vec![] } else { vec![(0, vec![10 * t.rank() as u8])] };
    ///     let from: &[u32] = if t.rank() == 0 { &[2, 1] } else { &[] };
    ///     t.exchange(7, sends, from).unwrap()
    /// });
    /// assert_eq!(got[0], [vec![20], vec![10]]);
    /// assert!(got[1].is_empty() && got[2].is_empty());
    /// ```
    fn exchange(&mut self, tag: u32, sends: Vec<(u32, Vec<u8>)>, from: &[u32]) -> Result<Vec<Vec<u8>>, TransportError>;

    /// Waits until every rank has called it (through rank 0, with empty messages and tag
    /// [`BARRIER_TAG`]), so that timings after it measure compositing, not rendering imbalance.
    ///
    /// ```
    /// use std::sync::atomic::{AtomicU32, Ordering};
    /// use strahl::composite::{ThreadTransport, Transport};
    /// let arrived = AtomicU32::new(0);
    /// let seen = ThreadTransport::run(4, |t| {
    ///     arrived.fetch_add(1, Ordering::SeqCst);
    ///     t.barrier().unwrap();
    ///     arrived.load(Ordering::SeqCst) // no rank gets past until all four have arrived
    /// });
    /// assert_eq!(seen, [4; 4]);
    /// ```
    fn barrier(&mut self) -> Result<(), TransportError> {
        let (me, p) = (self.rank(), self.size());
        if me == 0 {
            let others: Vec<u32> = (1..p).collect();
            self.exchange(BARRIER_TAG, Vec::new(), &others)?;
            self.exchange(BARRIER_TAG + 1, others.iter().map(|&r| (r, Vec::new())).collect(), &[])?;
        } else {
            self.exchange(BARRIER_TAG, vec![(0, Vec::new())], &[])?;
            self.exchange(BARRIER_TAG + 1, Vec::new(), &[0])?;
        }
        Ok(())
    }
}

/// Tags from this value up are reserved for [`Transport::barrier`]; compositing uses small tags
/// (the round number).
///
/// ```
/// use strahl::composite::{exec::BARRIER_TAG, schedule::MAX_ROUNDS};
/// // Compositing tags (the rounds, then the gather) stay below the barrier's,
/// assert!((MAX_ROUNDS as u32) < BARRIER_TAG);
/// // and the barrier's two tags are in MPI's guaranteed range (up to 32767).
/// assert!(BARRIER_TAG + 1 <= 32767);
/// ```
pub const BARRIER_TAG: u32 = 0x7000;

/// A transport failure (a peer went away, or MPI reported an error).
///
/// ```
/// use strahl::composite::{ThreadTransport, Transport, TransportError};
/// let mut t = ThreadTransport::group(1).remove(0);
/// let err = t.exchange(0, vec![(5, vec![1])], &[]).unwrap_err();
/// assert_eq!(err, TransportError("no such rank"));
/// assert_eq!(err.to_string(), "transport: no such rank");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TransportError(pub &'static str);

impl core::fmt::Display for TransportError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "transport: {}", self.0)
    }
}

impl core::error::Error for TransportError {}

/// `t.exchange`, with the answer checked to hold one message per rank of `from`: a transport that
/// returns fewer (or more) is an error here, not a panic or a piece of the image left out.
fn exchange_checked<T: Transport + ?Sized>(
    t: &mut T,
    tag: u32,
    sends: Vec<(u32, Vec<u8>)>,
    from: &[u32],
) -> Result<Vec<Vec<u8>>, TransportError> {
    let got = t.exchange(tag, sends, from)?;
    if got.len() != from.len() {
        return Err(TransportError(
            "the transport returned another number of messages than ranks asked",
        ));
    }
    Ok(got)
}

/// Why compositing failed.
///
/// ```
/// use strahl::composite::{CompositeError, KVec, Pixel, Plan, RgbaF32, Schedule, ThreadTransport, composite};
/// let mut t = ThreadTransport::group(1).remove(0);
/// // A k-vector for two ranks on a group of one.
/// let plan = Plan { schedule: Schedule::RadixK(KVec::direct_send(2)), order: &[0], root: 0, sparse: true };
/// let err = composite(&mut t, &[RgbaF32::EMPTY; 4], &plan).unwrap_err();
/// assert_eq!(err, CompositeError::BadPlan);
/// assert_eq!(err.to_string(), "compositing plan does not match the ranks");
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum CompositeError {
    /// The order is not a permutation of `0 .. size`, or the k-vector's product is not `size`.
    BadPlan,
    /// The image is larger than `u32::MAX` pixels.
    ImageTooLarge,
    /// The transport failed.
    Transport(TransportError),
    /// A received message was malformed.
    Decode(DecodeError),
}

impl core::fmt::Display for CompositeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadPlan => f.write_str("compositing plan does not match the ranks"),
            Self::ImageTooLarge => f.write_str("image has more than u32::MAX pixels"),
            Self::Transport(e) => write!(f, "{e}"),
            Self::Decode(e) => write!(f, "{e}"),
        }
    }
}

impl core::error::Error for CompositeError {}

impl From<TransportError> for CompositeError {
    fn from(e: TransportError) -> Self {
        Self::Transport(e)
    }
}

impl From<DecodeError> for CompositeError {
    fn from(e: DecodeError) -> Self {
        Self::Decode(e)
    }
}

/// Which schedule to run.
///
/// ```
/// use strahl::composite::{DepthPixel, KVec, Plan, Schedule, ThreadTransport, Transport, composite};
/// let order = [0, 1, 2, 3];
/// for schedule in [Schedule::Tree, Schedule::RadixK(KVec::new(&[2, 2]).unwrap())] {
///     let out = ThreadTransport::run(4, |t| {
///         let img = vec![DepthPixel::new(t.rank() as f32, t.rank()); 5];
///         let plan = Plan { schedule, order: &order, root: 0, sparse: true };
///         composite(t, &img, &plan).unwrap().0
///     });
///     assert!(out[0].as_ref().unwrap().iter().all(|p| p.depth() == 0.0)); // rank 0's samples are nearest
/// }
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Schedule {
    /// Radix-k with the given k-vector (direct-send `[P]`, binary-swap `[2, .., 2]`, or any).
    RadixK(KVec),
    /// The naive binary tree reduction of whole images.
    Tree,
}

/// What to composite and how.
///
/// ```
/// use strahl::composite::{Plan, RgbaF32, Schedule, ThreadTransport, Transport, composite};
/// let (red, green) = (RgbaF32([1.0, 0.0, 0.0, 1.0]), RgbaF32([0.0, 1.0, 0.0, 1.0]));
/// let order = [1, 0]; // rank 1 is nearer the viewer than rank 0
/// let out = ThreadTransport::run(2, |t| {
///     let plan = Plan { schedule: Schedule::Tree, order: &order, root: 1, sparse: false };
///     composite(t, &[if t.rank() == 1 { red } else { green }; 3], &plan).unwrap().0
/// });
/// assert!(out[0].is_none()); // only the root gets the image
/// assert_eq!(out[1], Some(vec![red; 3]));
/// ```
#[derive(Clone, Debug)]
pub struct Plan<'a> {
    /// The schedule.
    pub schedule: Schedule,
    /// Visibility order: `order[v]` is the transport rank whose image is `v`-th from the viewer.
    /// For depth compositing any permutation gives the same image.
    pub order: &'a [u32],
    /// The transport rank that receives the final image.
    pub root: u32,
    /// Send only non-empty pixels (run-length encoded); `false` sends every pixel.
    pub sparse: bool,
}

/// What one rank did.
///
/// ```
/// use strahl::composite::{KVec, Plan, RgbaF32, Schedule, ThreadTransport, composite};
/// let order = [0, 1];
/// let stats = ThreadTransport::run(2, |t| {
///     let plan = Plan { schedule: Schedule::RadixK(KVec::direct_send(2)), order: &order, root: 0, sparse: true };
///     composite(t, &[RgbaF32([0.5; 4]); 10], &plan).unwrap().1
/// });
/// // Each rank sends the other one half: a header of one run (16 bytes) and 5 pixels of 16 bytes.
/// assert_eq!((stats[0].messages, stats[0].bytes_sent), (1, 16 + 5 * 16));
/// assert_eq!((stats[0].gather_bytes, stats[1].gather_bytes), (0, 16 + 5 * 16)); // rank 1 to the root
/// assert_eq!(stats[0].round_seconds.len(), 2); // one round, then the gather
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompositeStats {
    /// Bytes this rank sent during the compositing rounds (headers included, final gather not).
    pub bytes_sent: u64,
    /// Bytes this rank sent in the final gather.
    pub gather_bytes: u64,
    /// Messages sent during the rounds.
    pub messages: u32,
    /// Wall time of each round and then of the gather, in seconds (zeros without `std`).
    pub round_seconds: Vec<f64>,
}

fn now() -> f64 {
    #[cfg(feature = "std")]
    {
        use std::sync::OnceLock;
        use std::time::Instant;
        static T0: OnceLock<Instant> = OnceLock::new();
        T0.get_or_init(Instant::now).elapsed().as_secs_f64()
    }
    #[cfg(not(feature = "std"))]
    {
        0.0
    }
}

/// Composites this rank's full-size partial `image` with every other rank's: returns the final
/// image on `plan.root` (`Some`) and `None` elsewhere, with statistics. Every rank must call it with
/// the same plan and image size.
///
/// ```
/// use strahl::composite::{DepthPixel, KVec, Plan, Schedule, ThreadTransport, Transport, composite, composite_serial};
/// let images: Vec<Vec<DepthPixel>> = (0..3)
///     .map(|r| (0..10).map(|i| DepthPixel::new(((i * 7 + r * 3) % 5) as f32, r)).collect())
///     .collect();
/// let order = [0, 1, 2];
/// let results = ThreadTransport::run(3, |t| {
///     let plan = Plan { schedule: Schedule::RadixK(KVec::direct_send(3)), order: &order, root: 0, sparse: true };
///     composite(t, &images[t.rank() as usize], &plan).unwrap().0
/// });
/// let serial = composite_serial(&images.iter().map(|v| v.as_slice()).collect::<Vec<_>>());
/// assert_eq!(results[0].as_deref(), Some(serial.as_slice()));
/// ```
pub fn composite<P: Pixel, T: Transport>(
    t: &mut T,
    image: &[P],
    plan: &Plan<'_>,
) -> Result<(Option<Vec<P>>, CompositeStats), CompositeError> {
    let p = t.size();
    let me = t.rank();
    if plan.order.len() != p as usize || plan.root >= p {
        return Err(CompositeError::BadPlan);
    }
    let mut seen = vec![false; p as usize];
    for &r in plan.order {
        if r >= p || core::mem::replace(&mut seen[r as usize], true) {
            return Err(CompositeError::BadPlan);
        }
    }
    let n = u32::try_from(image.len()).map_err(|_| CompositeError::ImageTooLarge)?;
    let v = plan.order.iter().position(|&r| r == me).unwrap_or(0) as u32;
    let real = |v: u32| plan.order[v as usize];
    let mut stats = CompositeStats::default();
    let mut acc = image.to_vec();
    let mut t0 = now();
    let mut lap = |stats: &mut CompositeStats| {
        let t1 = now();
        stats.round_seconds.push(t1 - t0);
        t0 = t1;
    };

    // The range this rank owns at the end, and the tag base of the gather.
    let (owned, gather_tag) = match plan.schedule {
        Schedule::RadixK(kvec) => {
            if kvec.ranks() != p {
                return Err(CompositeError::BadPlan);
            }
            let s = RadixK::new(kvec, n);
            for round in 0..kvec.rounds() {
                let mut sends = Vec::new();
                for m in s.sends(v, round) {
                    let mut wire = Vec::new();
                    encode(
                        &acc[m.range.start as usize..m.range.end as usize],
                        plan.sparse,
                        &mut wire,
                    );
                    stats.bytes_sent += wire.len() as u64;
                    stats.messages += 1;
                    sends.push((real(m.to), wire));
                }
                let from: Vec<u32> = s.receives(v, round).map(|m| real(m.from)).collect();
                let got = exchange_checked(t, round as u32, sends, &from)?;
                // Blend in visibility order around our own piece (digit d).
                let d = s.digit(v, round);
                let mine = s.receives(v, round).next().map(|m| m.range).unwrap_or(0..0);
                let region = &mut acc[mine.start as usize..mine.end as usize];
                let mut members = s.receives(v, round).map(|m| m.from).zip(got.iter());
                // Members in front of us (digits < d) composite in front, nearest last.
                let front: Vec<_> = members.by_ref().take(d as usize).collect();
                for (_, wire) in front.iter().rev() {
                    decode_composite(wire, region, false)?;
                }
                for (_, wire) in members {
                    decode_composite(wire, region, true)?;
                }
                lap(&mut stats);
            }
            (s.final_region(v), kvec.rounds() as u32)
        }
        Schedule::Tree => {
            let rounds = tree_rounds(p);
            for round in 0..rounds {
                if let Some((w, receive)) = tree_partner(v, round, p) {
                    if receive {
                        let got = exchange_checked(t, round, Vec::new(), &[real(w)])?;
                        decode_composite(&got[0], &mut acc, true)?;
                    } else {
                        let mut wire = Vec::new();
                        encode(&acc, plan.sparse, &mut wire);
                        stats.bytes_sent += wire.len() as u64;
                        stats.messages += 1;
                        t.exchange(round, vec![(real(w), wire)], &[])?;
                    }
                }
                lap(&mut stats);
            }
            (if v == 0 { 0..n } else { 0..0 }, rounds)
        }
    };

    // Gather the owned ranges on the root.
    let mut out = None;
    if me == plan.root {
        let mut img = vec![P::EMPTY; n as usize];
        img[owned.start as usize..owned.end as usize].copy_from_slice(&acc[owned.start as usize..owned.end as usize]);
        let owners: Vec<(u32, core::ops::Range<u32>)> = (0..p)
            .filter(|&w| real(w) != me)
            .map(|w| (w, owned_range(&plan.schedule, w, n)))
            .filter(|(_, r)| !r.is_empty())
            .collect();
        let from: Vec<u32> = owners.iter().map(|(w, _)| real(*w)).collect();
        let got = exchange_checked(t, gather_tag, Vec::new(), &from)?;
        for ((_, r), wire) in owners.iter().zip(&got) {
            decode_composite(wire, &mut img[r.start as usize..r.end as usize], true)?;
        }
        out = Some(img);
    } else if !owned.is_empty() {
        let mut wire = Vec::new();
        encode(&acc[owned.start as usize..owned.end as usize], plan.sparse, &mut wire);
        stats.gather_bytes += wire.len() as u64;
        t.exchange(gather_tag, vec![(plan.root, wire)], &[])?;
    }
    lap(&mut stats);
    Ok((out, stats))
}

fn owned_range(s: &Schedule, v: u32, n: u32) -> core::ops::Range<u32> {
    match s {
        Schedule::RadixK(k) => RadixK::new(*k, n).final_region(v),
        Schedule::Tree => {
            if v == 0 {
                0..n
            } else {
                0..0
            }
        }
    }
}

/// Measures the [`CostModel`](super::CostModel) of this transport (`std`): latency and bandwidth from ping-pongs
/// between ranks 0 and 1 (median of repeats), the blend rate from compositing on this rank; rank
/// 0's figures are sent to every rank so that all choose the same k-vector. Every rank must call it.
/// With one rank only the blend rate is measured (messages cost nothing).
///
/// ```
/// use strahl::composite::{ThreadTransport, measure_cost_model};
/// let models = ThreadTransport::run(2, |t| measure_cost_model(t).unwrap());
/// assert_eq!(models[0], models[1]);
/// assert!(models[0].latency > 0.0 && models[0].seconds_per_byte > 0.0);
/// ```
#[cfg(feature = "std")]
pub fn measure_cost_model<T: Transport>(t: &mut T) -> Result<super::CostModel, TransportError> {
    use std::time::Instant;
    const TAG: u32 = BARRIER_TAG + 16;
    let (me, p) = (t.rank(), t.size());
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    // Blend rate: 64 Ki RGBA f32 pixels composited a few times.
    let mut acc = vec![super::RgbaF32([0.1, 0.2, 0.3, 0.5]); 1 << 16];
    let other = vec![super::RgbaF32([0.3, 0.2, 0.1, 0.4]); 1 << 16];
    let blend = median(
        (0..5)
            .map(|_| {
                let t0 = Instant::now();
                <super::RgbaF32 as Pixel>::composite_behind(&mut acc, &other);
                t0.elapsed().as_secs_f64() / acc.len() as f64
            })
            .collect(),
    );
    let mut model = super::CostModel {
        latency: 0.0,
        seconds_per_byte: 0.0,
        seconds_per_blend: blend,
    };
    if p < 2 {
        return Ok(model);
    }
    // Ping-pong between ranks 0 and 1: round trips of `bytes`, median of `reps`.
    let pingpong = |t: &mut T, bytes: usize, reps: usize| -> Result<f64, TransportError> {
        let mut times = Vec::new();
        for r in 0..reps as u32 {
            let t0 = Instant::now();
            if me == 0 {
                t.exchange(TAG + 2 * r, vec![(1, vec![0u8; bytes])], &[])?;
                t.exchange(TAG + 2 * r + 1, Vec::new(), &[1])?;
            } else if me == 1 {
                let got = exchange_checked(t, TAG + 2 * r, Vec::new(), &[0])?;
                t.exchange(TAG + 2 * r + 1, got.into_iter().map(|b| (0, b)).collect(), &[])?;
            }
            times.push(t0.elapsed().as_secs_f64() / 2.0);
        }
        Ok(median(times))
    };
    if me <= 1 {
        let lat = pingpong(t, 0, 21)?;
        let mib = 1 << 20;
        let big = pingpong(t, mib, 5)?;
        model.latency = lat.max(1e-9);
        model.seconds_per_byte = ((big - lat) / mib as f64).max(1e-13);
    }
    // Rank 0's figures to everyone.
    let tag = TAG + 100;
    if me == 0 {
        let bytes: Vec<u8> = [model.latency, model.seconds_per_byte, model.seconds_per_blend]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        t.exchange(tag, (1..p).map(|r| (r, bytes.clone())).collect(), &[])?;
    } else {
        let got = exchange_checked(t, tag, Vec::new(), &[0])?;
        let f = |i: usize| {
            got[0]
                .get(8 * i..8 * i + 8)
                .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                .unwrap_or(0.0)
        };
        model = super::CostModel {
            latency: f(0),
            seconds_per_byte: f(1),
            seconds_per_blend: f(2),
        };
    }
    Ok(model)
}

/// The serial reference: `images` in visibility order (nearest first) composited front to back.
///
/// ```
/// use strahl::composite::{Pixel, RgbaF32, composite_serial};
/// let front = [RgbaF32([0.5, 0.0, 0.0, 0.5]), RgbaF32::EMPTY];
/// let back = [RgbaF32([0.0, 1.0, 0.0, 1.0]); 2];
/// let img = composite_serial(&[&front[..], &back[..]]);
/// assert_eq!(img, [RgbaF32([0.5, 0.5, 0.0, 1.0]), RgbaF32([0.0, 1.0, 0.0, 1.0])]);
/// ```
pub fn composite_serial<P: Pixel>(images: &[&[P]]) -> Vec<P> {
    let n = images.iter().map(|i| i.len()).max().unwrap_or(0);
    let mut acc = vec![P::EMPTY; n];
    for img in images {
        let m = img.len().min(n);
        P::composite_behind(&mut acc[..m], &img[..m]);
    }
    acc
}
