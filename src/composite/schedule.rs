//! Sort-last compositing schedules as pure data (core-only): for `P` ranks and a k-vector
//! `[k1, .., kr]` with `k1 k2 .. kr = P`, which rank sends which pixel range to whom in each round.
//!
//! Radix-k (Peterka, Goodell, Ross, Shen, Thakur, "A configurable algorithm for parallel
//! image-compositing applications", SC 2009) covers the classic schedules: **direct-send** is
//! `[P]` (Hsu 1993), **binary-swap** is `[2, 2, .., 2]` (Ma et al. 1994). The naive **tree
//! reduction** (whole images sent up a binary tree) is here too, for comparison.
//!
//! # Ranks, digits and visibility order
//! Schedules work on *virtual* ranks `v = 0 .. P`, which the executor maps to transport ranks
//! through a visibility order (virtual rank 0 is nearest the viewer). Write `v` in the mixed radix
//! of the k-vector, digit 0 least significant: `v = d0 + k1 (d1 + k2 (d2 + ..))`. In round `i` the
//! ranks that differ only in digit `i` form a group of `k_(i+1)` ranks; they hold the same pixel
//! range, split it into `k` pieces, and member `d` gathers and composites piece `d`. Each group
//! covers consecutive blocks of virtual ranks, so blending the `k` pieces in digit order is
//! blending in visibility order, and "over" stays correct.
//!
//! Pixel ranges are scanline-order index ranges of the image; a range of `n` pixels splits into
//! pieces `[j n / k, (j + 1) n / k)`, so every size works (odd, prime, smaller than `P`).
//!
//! # Cost
//! Each rank sends `sum_i (k_i - 1) / k_i n_i` pixels with `n_i = n / (k_1 .. k_(i-1))`, which
//! telescopes to `n (1 - 1/P)` for every k-vector (up to one pixel per piece from uneven splits);
//! the k-vector trades the number of messages (`sum (k_i - 1)`) against the rounds. [`CostModel`]
//! and [`auto_kvec`] pick one.

use core::ops::Range;

/// Most rounds a k-vector can have (every factor is at least 2 and `P` fits in `u32`).
///
/// ```
/// use strahl::composite::{KVec, schedule::MAX_ROUNDS};
/// assert_eq!(KVec::binary_swap(1 << 31).unwrap().rounds(), 31);
/// assert!(KVec::new(&[2; MAX_ROUNDS + 1]).is_none());
/// ```
pub const MAX_ROUNDS: usize = 32;

/// A k-vector: the group size of each round; the product is the number of ranks.
///
/// ```
/// use strahl::composite::KVec;
/// let k = KVec::new(&[3, 2]).unwrap();
/// assert_eq!(k.ranks(), 6);
/// assert_eq!(KVec::binary_swap(8).unwrap().as_slice(), &[2, 2, 2]);
/// assert_eq!(KVec::binary_swap(6), None); // not a power of two
/// assert_eq!(KVec::direct_send(7).as_slice(), &[7]);
/// ```
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct KVec {
    k: [u32; MAX_ROUNDS],
    len: usize,
}

impl core::fmt::Debug for KVec {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list().entries(self.as_slice()).finish()
    }
}

impl KVec {
    /// A k-vector from its factors, each at least 2 (`[]` is the single-rank case `P = 1`);
    /// `None` if a factor is below 2, there are more than [`MAX_ROUNDS`], or the product overflows.
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// assert_eq!(KVec::new(&[4, 2]).unwrap().ranks(), 8);
    /// assert_eq!(KVec::new(&[]).unwrap().ranks(), 1); // one rank, no rounds
    /// assert!(KVec::new(&[1, 8]).is_none()); // a factor below 2
    /// assert!(KVec::new(&[1 << 16, 1 << 16]).is_none()); // the product overflows `u32`
    /// ```
    pub fn new(factors: &[u32]) -> Option<Self> {
        if factors.len() > MAX_ROUNDS || factors.iter().any(|&k| k < 2) {
            return None;
        }
        factors.iter().try_fold(1u32, |p, &k| p.checked_mul(k))?;
        let mut k = [0; MAX_ROUNDS];
        k[..factors.len()].copy_from_slice(factors);
        Some(Self { k, len: factors.len() })
    }

    /// Direct-send: one round, all `p` ranks in one group (`[]` for `p <= 1`).
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::direct_send(4), 100);
    /// assert_eq!(s.sends(0, 0).count(), 3); // one piece to each other rank
    /// assert_eq!(KVec::direct_send(1).rounds(), 0); // one rank: nothing to send
    /// ```
    pub fn direct_send(p: u32) -> Self {
        if p <= 1 { Self::new(&[]) } else { Self::new(&[p]) }.unwrap_or(Self {
            k: [0; MAX_ROUNDS],
            len: 0,
        })
    }

    /// Binary-swap, `[2, 2, .., 2]`; `None` unless `p` is a power of two.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::binary_swap(8).unwrap(), 64);
    /// assert!((0..3).all(|round| s.sends(5, round).count() == 1)); // one partner per round
    /// assert_eq!(s.final_region(5), 40..48); // halved three times
    /// assert_eq!(KVec::binary_swap(12), None);
    /// ```
    pub fn binary_swap(p: u32) -> Option<Self> {
        if !p.is_power_of_two() {
            return None;
        }
        let mut k = [0; MAX_ROUNDS];
        let len = p.trailing_zeros() as usize;
        k[..len].fill(2);
        Some(Self { k, len })
    }

    /// The factors.
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// assert_eq!(KVec::new(&[3, 2]).unwrap().as_slice(), &[3, 2]);
    /// ```
    pub fn as_slice(&self) -> &[u32] {
        &self.k[..self.len]
    }

    /// Number of rounds.
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// assert_eq!(KVec::binary_swap(16).unwrap().rounds(), 4);
    /// ```
    pub fn rounds(&self) -> usize {
        self.len
    }

    /// The number of ranks, the product of the factors.
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// assert_eq!(KVec::new(&[3, 2, 2]).unwrap().ranks(), 12);
    /// ```
    pub fn ranks(&self) -> u32 {
        self.as_slice().iter().product()
    }

    /// Product of the factors of rounds before `round` (the digit's place value).
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// let k = KVec::new(&[3, 2, 2]).unwrap();
    /// assert_eq!([k.stride(0), k.stride(1), k.stride(2), k.stride(3)], [1, 3, 6, 12]);
    /// assert_eq!(k.stride(9), 12); // past the last round: all the factors
    /// ```
    pub fn stride(&self, round: usize) -> u32 {
        self.as_slice()[..round.min(self.len)].iter().product()
    }

    /// The group size of `round`: its factor, and 1 past the last round (where every rank is a
    /// group of its own, with nothing to send).
    ///
    /// ```
    /// use strahl::composite::KVec;
    /// let k = KVec::new(&[3, 2]).unwrap();
    /// assert_eq!([k.factor(0), k.factor(1), k.factor(2)], [3, 2, 1]);
    /// ```
    pub fn factor(&self, round: usize) -> u32 {
        self.as_slice().get(round).copied().unwrap_or(1)
    }
}

/// One message of a round: `from` sends the pixels `range` to `to` (virtual ranks).
///
/// ```
/// use strahl::composite::{KVec, Message, RadixK};
/// let s = RadixK::new(KVec::binary_swap(2).unwrap(), 10);
/// let sent: Vec<Message> = s.sends(0, 0).collect();
/// assert_eq!(sent, [Message { from: 0, to: 1, range: 5..10 }]); // rank 0 keeps the first half
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Message {
    /// Sending virtual rank.
    pub from: u32,
    /// Receiving virtual rank.
    pub to: u32,
    /// Pixel index range.
    pub range: Range<u32>,
}

/// Piece `j` of `k` of the pixel range `r`: `[j n / k, (j + 1) n / k)` relative to its start.
///
/// ```
/// use strahl::composite::piece;
/// assert_eq!(piece(&(0..10), 0, 3), 0..3);
/// assert_eq!(piece(&(0..10), 1, 3), 3..6);
/// assert_eq!(piece(&(0..10), 2, 3), 6..10); // uneven pieces differ by at most one pixel
/// assert!(piece(&(100..102), 0, 4).is_empty()); // more pieces than pixels: some are empty
/// // Out of range: no pieces (`k == 0`), a piece past the last, a reversed range: all empty.
/// assert!(piece(&(0..10), 0, 0).is_empty() && piece(&(0..10), 3, 3).is_empty());
/// assert!(piece(&core::ops::Range { start: 10, end: 0 }, 0, 2).is_empty());
/// ```
pub fn piece(r: &Range<u32>, j: u32, k: u32) -> Range<u32> {
    if k == 0 || j >= k {
        return r.start..r.start;
    }
    let n = r.end.saturating_sub(r.start) as u64;
    // `j + 1 <= k`, so `at` stays within `r.start..=r.end`.
    let at = |j: u32| r.start + (j as u64 * n / k as u64) as u32;
    at(j)..at(j + 1)
}

/// The radix-k schedule of one virtual rank: its group and pixel ranges round by round.
///
/// ```
/// use strahl::composite::{KVec, RadixK};
/// // 6 ranks as [3, 2], an image of 100 pixels.
/// let s = RadixK::new(KVec::new(&[3, 2]).unwrap(), 100);
/// assert_eq!(s.group(4, 0), [3, 4, 5]); // round 0: ranks differing in digit 0
/// assert_eq!(s.group(4, 1), [1, 4]); // round 1: digit 1 (stride 3)
/// assert_eq!(s.region(4, 1), 33..66); // after round 0, rank 4 (digit 1) holds piece 1 of 3
/// assert_eq!(s.final_region(4), 49..66);
/// // Every rank's final range tiles the image.
/// let total: u32 = (0..6).map(|v| s.final_region(v).len() as u32).sum();
/// assert_eq!(total, 100);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct RadixK {
    /// The group sizes per round.
    pub kvec: KVec,
    /// Pixels in the image.
    pub pixels: u32,
}

/// Up to this many members per group are returned inline by [`RadixK::group`].
///
/// ```
/// use strahl::composite::{KVec, RadixK, schedule::MAX_GROUP};
/// let s = RadixK::new(KVec::direct_send(100), 1000);
/// assert_eq!(s.group(0, 0).len(), MAX_GROUP); // truncated: 100 members
/// ```
pub const MAX_GROUP: usize = 64;

/// A small inline list of virtual ranks (a group).
///
/// ```
/// use strahl::composite::{KVec, RadixK};
/// let g = RadixK::new(KVec::direct_send(4), 8).group(2, 0);
/// assert_eq!(g, [0, 1, 2, 3]);
/// assert_eq!(g.iter().sum::<u32>(), 6); // derefs to `[u32]`
/// ```
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Group {
    ranks: [u32; MAX_GROUP],
    len: usize,
}

impl core::ops::Deref for Group {
    type Target = [u32];
    fn deref(&self) -> &[u32] {
        &self.ranks[..self.len]
    }
}

impl core::fmt::Debug for Group {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

impl<const N: usize> PartialEq<[u32; N]> for Group {
    fn eq(&self, other: &[u32; N]) -> bool {
        **self == other[..]
    }
}

impl RadixK {
    /// The schedule for `kvec` over an image of `pixels` pixels.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::new(&[2, 3]).unwrap(), 60);
    /// assert_eq!((s.kvec.ranks(), s.pixels), (6, 60));
    /// ```
    pub fn new(kvec: KVec, pixels: u32) -> Self {
        Self { kvec, pixels }
    }

    /// Digit `round` of virtual rank `v`.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::new(&[3, 2]).unwrap(), 100);
    /// assert_eq!((s.digit(5, 0), s.digit(5, 1)), (2, 1)); // 5 = 2 + 3 * 1
    /// assert_eq!(s.digit(5, 2), 0); // past the last round ([`KVec::factor`] is 1)
    /// ```
    pub fn digit(&self, v: u32, round: usize) -> u32 {
        (v / self.kvec.stride(round)) % self.kvec.factor(round)
    }

    /// The members of `v`'s group in `round`, in digit (= visibility) order. Groups larger than
    /// [`MAX_GROUP`] are truncated; [`auto_kvec`] never makes them and [`KVec::direct_send`] users
    /// with more ranks should call [`RadixK::member`] instead.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::binary_swap(8).unwrap(), 64);
    /// assert_eq!(s.group(5, 0), [4, 5]); // 5 = 0b101: flip bit 0,
    /// assert_eq!(s.group(5, 1), [5, 7]); // then bit 1,
    /// assert_eq!(s.group(5, 2), [1, 5]); // then bit 2
    /// assert_eq!(s.group(5, 3), [5]); // past the last round: alone
    /// ```
    pub fn group(&self, v: u32, round: usize) -> Group {
        let k = self.kvec.factor(round);
        let mut g = Group {
            ranks: [0; MAX_GROUP],
            len: (k as usize).min(MAX_GROUP),
        };
        for j in 0..g.len as u32 {
            g.ranks[j as usize] = self.member(v, round, j);
        }
        g
    }

    /// Member `j` (digit `j`) of `v`'s group in `round`.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::new(&[3, 2]).unwrap(), 100);
    /// assert_eq!(s.member(4, 1, 0), 1); // 4's group in round 1 is [1, 4]
    /// let s = RadixK::new(KVec::direct_send(100), 1000);
    /// assert_eq!(s.member(7, 0, 99), 99); // past `MAX_GROUP`, where `group` truncates
    /// ```
    pub fn member(&self, v: u32, round: usize, j: u32) -> u32 {
        let s = self.kvec.stride(round);
        // `digit * s <= v`; a `j` past the group saturates instead of overflowing.
        (v - self.digit(v, round) * s).saturating_add(j.saturating_mul(s))
    }

    /// The pixel range `v` holds at the start of `round` (`round == rounds` gives the final one).
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::binary_swap(4).unwrap(), 100);
    /// assert_eq!(s.region(3, 0), 0..100); // every rank starts with the whole image
    /// assert_eq!(s.region(3, 1), 50..100);
    /// assert_eq!(s.region(3, 2), 75..100); // `round == rounds`: the final range
    /// ```
    pub fn region(&self, v: u32, round: usize) -> Range<u32> {
        let mut r = 0..self.pixels;
        for i in 0..round.min(self.kvec.rounds()) {
            r = piece(&r, self.digit(v, i), self.kvec.factor(i));
        }
        r
    }

    /// The pixel range `v` owns after the last round.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::direct_send(3), 10);
    /// let owned: Vec<_> = (0..3).map(|v| s.final_region(v)).collect();
    /// assert_eq!(owned, [0..3, 3..6, 6..10]);
    /// ```
    pub fn final_region(&self, v: u32) -> Range<u32> {
        self.region(v, self.kvec.rounds())
    }

    /// The messages `v` sends in `round`: piece `j` of its range to member `j`, for `j != digit`.
    ///
    /// ```
    /// use strahl::composite::{KVec, Message, RadixK};
    /// let s = RadixK::new(KVec::direct_send(3), 9);
    /// let sent: Vec<Message> = s.sends(1, 0).collect();
    /// assert_eq!(sent, [Message { from: 1, to: 0, range: 0..3 }, Message { from: 1, to: 2, range: 6..9 }]);
    /// // Every send is one of its receiver's receives.
    /// assert!(sent.iter().all(|m| s.receives(m.to, 0).any(|r| r == *m)));
    /// assert_eq!(s.sends(1, 1).count() + s.receives(1, 1).count(), 0); // past the last round
    /// ```
    pub fn sends(&self, v: u32, round: usize) -> impl Iterator<Item = Message> + '_ {
        let k = self.kvec.factor(round);
        let d = self.digit(v, round);
        let r = self.region(v, round);
        (0..k).filter(move |&j| j != d).map(move |j| Message {
            from: v,
            to: self.member(v, round, j),
            range: piece(&r, j, k),
        })
    }

    /// The messages `v` receives in `round`, in visibility order: piece `digit` from every member.
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::direct_send(3), 9);
    /// let from: Vec<u32> = s.receives(1, 0).map(|m| m.from).collect();
    /// assert_eq!(from, [0, 2]); // nearest first
    /// assert!(s.receives(1, 0).all(|m| m.range == (3..6))); // rank 1's piece from each
    /// ```
    pub fn receives(&self, v: u32, round: usize) -> impl Iterator<Item = Message> + '_ {
        let k = self.kvec.factor(round);
        let d = self.digit(v, round);
        let mine = piece(&self.region(v, round), d, k);
        (0..k).filter(move |&j| j != d).map(move |j| Message {
            from: self.member(v, round, j),
            to: v,
            range: mine.clone(),
        })
    }

    /// Pixels `v` sends over all rounds (before the final gather).
    ///
    /// ```
    /// use strahl::composite::{KVec, RadixK};
    /// let s = RadixK::new(KVec::binary_swap(4).unwrap(), 100);
    /// assert_eq!(s.pixels_sent(0), 50 + 25); // n (1 - 1/P)
    /// ```
    pub fn pixels_sent(&self, v: u32) -> u64 {
        (0..self.kvec.rounds())
            .flat_map(|i| self.sends(v, i))
            .map(|m| m.range.len() as u64)
            .sum()
    }
}

/// The naive tree reduction: in round `i`, virtual rank `v` with `v mod 2^(i+1) == 2^i` sends its
/// whole (accumulated) image to `v - 2^i`, which composites it behind its own. Rank 0 ends with
/// the image. `ceil(log2 P)` rounds, `n` pixels per message.
///
/// ```
/// use strahl::composite::tree_partner;
/// assert_eq!(tree_partner(3, 0, 4), Some((2, false))); // round 0: 3 sends to 2
/// assert_eq!(tree_partner(2, 0, 4), Some((3, true))); // ... and 2 receives from 3
/// assert_eq!(tree_partner(2, 1, 4), Some((0, false)));
/// assert_eq!(tree_partner(4, 0, 5), None); // 4 has no partner in round 0 of 5 ranks
/// ```
pub fn tree_partner(v: u32, round: u32, p: u32) -> Option<(u32, bool)> {
    let s = 1u32.checked_shl(round)?;
    let m = (v as u64) % (2 * s as u64);
    if m == s as u64 {
        Some((v - s, false))
    } else if m == 0 && (v as u64 + s as u64) < p as u64 {
        Some((v + s, true))
    } else {
        None
    }
}

/// Rounds of the tree reduction for `p` ranks: `ceil(log2 p)`.
///
/// ```
/// use strahl::composite::{tree_partner, tree_rounds};
/// assert_eq!([1, 2, 4, 5, 8].map(tree_rounds), [0, 1, 2, 3, 3]);
/// // With 5 ranks, rank 0 receives in every round (from 1, 2, then 4).
/// assert!((0..tree_rounds(5)).all(|round| tree_partner(0, round, 5).is_some_and(|(_, recv)| recv)));
/// ```
pub fn tree_rounds(p: u32) -> u32 {
    if p <= 1 { 0 } else { 32 - (p - 1).leading_zeros() }
}

/// A latency/bandwidth/blend cost model for choosing a k-vector (Peterka 2009, section 4): a
/// round with group size `k` on a range of `n_i` pixels costs
/// `(k - 1) (latency + bytes_per_pixel n_i / k seconds_per_byte + n_i / k seconds_per_blend)`.
///
/// ```
/// use strahl::composite::{CostModel, auto_kvec};
/// let m = CostModel::shared_memory();
/// let k = auto_kvec(16, 1 << 20, 16, &m);
/// assert_eq!(k.ranks(), 16);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostModel {
    /// Seconds per message.
    pub latency: f64,
    /// Seconds per byte sent.
    pub seconds_per_byte: f64,
    /// Seconds per pixel composited.
    pub seconds_per_blend: f64,
}

impl CostModel {
    /// Ranks on one machine (MPI over shared memory or threads): 5 us per message, 5 GB/s,
    /// 1 ns per blended pixel. Measured on the 2-core development machine to within a factor of
    /// two; [`auto_kvec`] is not sensitive to that.
    ///
    /// ```
    /// use strahl::composite::CostModel;
    /// let m = CostModel::shared_memory();
    /// assert_eq!((m.latency, m.seconds_per_blend), (5e-6, 1e-9));
    /// ```
    pub fn shared_memory() -> Self {
        Self {
            latency: 5e-6,
            seconds_per_byte: 1.0 / 5e9,
            seconds_per_blend: 1e-9,
        }
    }

    /// A cluster interconnect: 2 us latency, 10 GB/s, 1 ns per blend.
    ///
    /// ```
    /// use strahl::composite::CostModel;
    /// let (net, shm) = (CostModel::cluster(), CostModel::shared_memory());
    /// assert!(net.latency < shm.latency && net.seconds_per_byte < shm.seconds_per_byte);
    /// ```
    pub fn cluster() -> Self {
        Self {
            latency: 2e-6,
            seconds_per_byte: 1.0 / 1e10,
            seconds_per_blend: 1e-9,
        }
    }

    /// Modelled seconds of compositing `pixels` pixels of `bytes_per_pixel` with `kvec`.
    ///
    /// ```
    /// use strahl::composite::{CostModel, KVec};
    /// let (direct, swap) = (KVec::direct_send(8), KVec::binary_swap(8).unwrap());
    /// // Latency only: the cost counts messages, the sum of `k - 1`.
    /// let latency = CostModel { latency: 1.0, seconds_per_byte: 0.0, seconds_per_blend: 0.0 };
    /// assert_eq!((latency.cost(&direct, 1024, 1), latency.cost(&swap, 1024, 1)), (7.0, 3.0));
    /// // Bandwidth only: every k-vector sends n (1 - 1/P) pixels.
    /// let bandwidth = CostModel { latency: 0.0, seconds_per_byte: 1.0, seconds_per_blend: 0.0 };
    /// assert_eq!((bandwidth.cost(&direct, 1024, 1), bandwidth.cost(&swap, 1024, 1)), (896.0, 896.0));
    /// ```
    pub fn cost(&self, kvec: &KVec, pixels: u64, bytes_per_pixel: u64) -> f64 {
        let mut n = pixels as f64;
        let mut t = 0.0;
        for &k in kvec.as_slice() {
            t += self.round(k, n, bytes_per_pixel);
            n /= k as f64;
        }
        t
    }

    fn round(&self, k: u32, n: f64, b: u64) -> f64 {
        let piece = n / k as f64;
        (k - 1) as f64 * (self.latency + piece * b as f64 * self.seconds_per_byte + piece * self.seconds_per_blend)
    }
}

/// The k-vector with the least modelled cost among all ordered factorisations of `p` into factors
/// of at most [`MAX_GROUP`] (dynamic programming over the divisors of `p`). A prime `p` above
/// `MAX_GROUP` gives direct-send.
///
/// ```
/// use strahl::composite::{CostModel, KVec, auto_kvec};
/// let m = CostModel::shared_memory();
/// let k = auto_kvec(12, 1 << 20, 16, &m);
/// assert!(k.ranks() == 12 && m.cost(&k, 1 << 20, 16) <= m.cost(&KVec::direct_send(12), 1 << 20, 16));
/// // Costly messages: the fewest (the sum of `k - 1`), from 12 = 2 * 2 * 3.
/// let slow = CostModel { latency: 1.0, ..m };
/// assert_eq!(auto_kvec(12, 1 << 20, 16, &slow).as_slice().iter().map(|k| k - 1).sum::<u32>(), 4);
/// assert_eq!(auto_kvec(67, 1 << 20, 16, &m), KVec::direct_send(67)); // a prime above `MAX_GROUP`
/// ```
pub fn auto_kvec(p: u32, pixels: u64, bytes_per_pixel: u64, model: &CostModel) -> KVec {
    if p <= 1 {
        return KVec::direct_send(1);
    }
    // Divisors of p, ascending (at most 1536 for p < 2^32).
    const MAXD: usize = 1536;
    let mut divs = [0u32; MAXD];
    let mut nd = 0;
    let mut i = 1u32;
    while (i as u64) * (i as u64) <= p as u64 {
        if p.is_multiple_of(i) {
            for d in [i, p / i] {
                if nd < MAXD && !divs[..nd].contains(&d) {
                    divs[nd] = d;
                    nd += 1;
                }
            }
        }
        i += 1;
    }
    let divs = &mut divs[..nd];
    divs.sort_unstable();
    // best[a]: least cost to go from product divs[a] (done so far) to p; next[a]: the factor.
    let mut best = [f64::INFINITY; MAXD];
    let mut next = [0u32; MAXD];
    best[nd - 1] = 0.0;
    for a in (0..nd - 1).rev() {
        let m = divs[a];
        let n = pixels as f64 / m as f64;
        for b in a + 1..nd {
            let d = divs[b];
            if !d.is_multiple_of(m) {
                continue;
            }
            let k = d / m;
            if k as usize > MAX_GROUP && !(a == 0 && b == nd - 1) {
                continue;
            }
            let c = model.round(k, n, bytes_per_pixel) + best[b];
            if c < best[a] {
                best[a] = c;
                next[a] = k;
            }
        }
    }
    let mut f = [0u32; MAX_ROUNDS];
    let (mut len, mut m) = (0, 1u32);
    while m != p && len < MAX_ROUNDS {
        let a = divs.iter().position(|&d| d == m).unwrap_or(0);
        let k = next[a].max(1);
        if k < 2 {
            break;
        }
        f[len] = k;
        len += 1;
        m *= k;
    }
    KVec::new(&f[..len])
        .filter(|k| k.ranks() == p)
        .unwrap_or_else(|| KVec::direct_send(p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn factorisations(p: u32) -> [KVec; 4] {
        let two = KVec::binary_swap(p).unwrap_or(KVec::direct_send(p));
        let first = (2..=p).find(|k| p.is_multiple_of(*k)).unwrap_or(p);
        let mixed = if first < p {
            KVec::new(&[first, p / first]).unwrap()
        } else {
            KVec::direct_send(p)
        };
        [
            KVec::direct_send(p),
            two,
            mixed,
            auto_kvec(p, 1000, 16, &CostModel::shared_memory()),
        ]
    }

    /// Arguments out of range (a round past the last, a member past the group, ranks past the
    /// last, pieces of nothing) answer without a panic: a round past the last is a group of one
    /// that sends and receives nothing and keeps the final region.
    #[test]
    fn out_of_range_arguments_answer_without_panic() {
        for kvec in factorisations(12) {
            let rounds = kvec.rounds();
            let s = RadixK::new(kvec, 1000);
            for v in [0, 5, 11, 12, u32::MAX] {
                for round in rounds..rounds + 3 {
                    assert_eq!(s.digit(v, round), 0);
                    assert_eq!(s.group(v, round), [v]);
                    assert_eq!(s.sends(v, round).count() + s.receives(v, round).count(), 0);
                    assert_eq!(s.region(v, round), s.final_region(v));
                }
                for round in 0..rounds {
                    let _ = s.member(v, round, u32::MAX);
                    let _ = (
                        s.group(v, round),
                        s.sends(v, round).count(),
                        s.receives(v, round).count(),
                    );
                }
            }
        }
        for (r, j, k) in [
            (0..10, 0, 0),
            (0..10, 5, 3),
            (0..10, u32::MAX, u32::MAX),
            (Range { start: 10, end: 0 }, 0, 2),
            (0..u32::MAX, 1, 2),
        ] {
            let p = piece(&r, j, k);
            assert!(p.start <= p.end && p.end <= r.end.max(r.start), "{r:?} {j} {k}: {p:?}");
        }
    }

    #[test]
    fn final_regions_tile_the_image_and_groups_agree() {
        for p in 1..=16u32 {
            for kvec in factorisations(p) {
                assert_eq!(kvec.ranks(), p, "{kvec:?}");
                for n in [0u32, 1, 5, 17, 101, 1000] {
                    let s = RadixK::new(kvec, n);
                    let mut covered = 0;
                    let mut starts: [(u32, u32); 16] = [(0, 0); 16];
                    for v in 0..p {
                        let r = s.final_region(v);
                        covered += r.len() as u32;
                        starts[v as usize] = (r.start, r.end);
                    }
                    assert_eq!(covered, n, "p {p} {kvec:?} n {n}");
                    let mut sorted = starts[..p as usize].to_vec();
                    sorted.sort();
                    for w in sorted.windows(2) {
                        assert_eq!(w[0].1, w[1].0, "ranges must be disjoint and adjacent");
                    }
                    for round in 0..kvec.rounds() {
                        for v in 0..p {
                            let g = s.group(v, round);
                            for &m in g.iter() {
                                assert_eq!(s.region(m, round), s.region(v, round), "group members share a range");
                                assert_eq!(s.group(m, round), g);
                            }
                            // Every send is someone's receive.
                            for msg in s.sends(v, round) {
                                assert!(s.receives(msg.to, round).any(|r| r == msg));
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn pixels_sent_is_n_times_one_minus_one_over_p() {
        for p in 1..=16u32 {
            for kvec in factorisations(p) {
                let n = 100_003u32;
                let s = RadixK::new(kvec, n);
                for v in 0..p {
                    let sent = s.pixels_sent(v) as f64;
                    let bound = n as f64 * (1.0 - 1.0 / p as f64);
                    // Uneven splits: at most one pixel per piece more.
                    let slack: u32 = kvec.as_slice().iter().sum();
                    assert!(sent <= bound + slack as f64, "p {p} {kvec:?} v {v}: {sent} > {bound}");
                }
            }
        }
    }

    #[test]
    fn tree_reduction_reaches_rank_zero() {
        for p in 1..=17u32 {
            let mut has = [false; 17];
            has[0] = true;
            let mut merged = [1u32; 17]; // images merged into each rank
            for round in 0..tree_rounds(p) {
                let before = merged;
                for v in 0..p {
                    if let Some((w, receive)) = tree_partner(v, round, p) {
                        assert_eq!(tree_partner(w, round, p), Some((v, !receive)));
                        if receive {
                            merged[v as usize] += before[w as usize];
                        }
                    }
                }
            }
            assert_eq!(merged[0], p, "p {p}");
            assert!(has[0]);
        }
    }

    #[test]
    fn auto_kvec_is_the_cheapest_factorisation() {
        let m = CostModel::shared_memory();
        for p in [1u32, 2, 6, 7, 12, 16, 64, 96, 97, 1024] {
            for n in [1u64 << 10, 1 << 20, 1 << 24] {
                let k = auto_kvec(p, n, 16, &m);
                assert_eq!(k.ranks(), p);
                for other in factorisations(p) {
                    assert!(
                        m.cost(&k, n, 16) <= m.cost(&other, n, 16) * (1.0 + 1e-12),
                        "p {p} n {n}: {k:?} vs {other:?}"
                    );
                }
            }
        }
        // High latency favours few rounds of large groups; free messages favour more.
        let slow = CostModel { latency: 1.0, ..m };
        assert_eq!(auto_kvec(16, 1 << 20, 16, &slow).rounds(), 4); // messages: 4 x 1 = 4 < 15
        let big = CostModel {
            latency: 0.0,
            seconds_per_byte: 1.0,
            seconds_per_blend: 0.0,
        };
        let k = auto_kvec(16, 1 << 20, 16, &big);
        assert_eq!(k.ranks(), 16);
    }

    #[test]
    fn bad_k_vectors_are_rejected() {
        assert!(KVec::new(&[1, 4]).is_none());
        assert!(KVec::new(&[0]).is_none());
        assert!(KVec::new(&[65536, 65536]).is_none());
        assert_eq!(KVec::direct_send(0).ranks(), 1);
    }
}
