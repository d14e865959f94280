//! The MPI transport (feature `mpi`): ranks are MPI processes of a communicator, through the
//! `mpi` crate (rsmpi) over the system's MPI library (OpenMPI from Debian's `libopenmpi-dev`).
//!
//! Sends are non-blocking (`MPI_Isend`) and complete after the receives (`MPI_Probe` +
//! `MPI_Recv`), so an exchange in which every rank sends before it receives cannot deadlock.

use super::exec::{Transport, TransportError};
use mpi::topology::{Communicator, SimpleCommunicator};
use mpi::traits::{Destination, Source};
use std::vec::Vec;

/// One rank of an MPI communicator.
///
/// ```no_run
/// use strahl::composite::{MpiTransport, Transport};
/// let universe = mpi::initialize().expect("MPI is initialised once");
/// let mut t = MpiTransport::new(universe.world());
/// println!("rank {} of {}", t.rank(), t.size());
/// ```
pub struct MpiTransport {
    comm: SimpleCommunicator,
}

impl MpiTransport {
    /// Wraps a communicator (usually `universe.world()`).
    ///
    /// ```no_run
    /// use strahl::composite::{MpiTransport, Transport};
    /// let universe = mpi::initialize().expect("MPI is initialised once");
    /// let t = MpiTransport::new(universe.world());
    /// assert!(t.rank() < t.size());
    /// ```
    pub fn new(comm: SimpleCommunicator) -> Self {
        Self { comm }
    }

    /// The communicator, for the caller's own collectives.
    ///
    /// ```no_run
    /// use mpi::traits::CommunicatorCollectives;
    /// use strahl::composite::MpiTransport;
    /// let universe = mpi::initialize().expect("MPI is initialised once");
    /// let t = MpiTransport::new(universe.world());
    /// t.communicator().barrier(); // e.g. before timing a composite
    /// ```
    pub fn communicator(&self) -> &SimpleCommunicator {
        &self.comm
    }
}

impl Transport for MpiTransport {
    fn rank(&self) -> u32 {
        self.comm.rank() as u32
    }

    fn size(&self) -> u32 {
        self.comm.size() as u32
    }

    fn exchange(&mut self, tag: u32, sends: Vec<(u32, Vec<u8>)>, from: &[u32]) -> Result<Vec<Vec<u8>>, TransportError> {
        let size = self.size();
        if sends.iter().any(|(to, _)| *to >= size) || from.iter().any(|&f| f >= size) {
            return Err(TransportError("no such rank"));
        }
        let tag = (tag & 0x7fff) as i32; // MPI guarantees tags up to 32767
        let comm = &self.comm;
        Ok(mpi::request::scope(|scope| {
            let pending: Vec<_> = sends
                .iter()
                .map(|(to, data)| {
                    comm.process_at_rank(*to as i32)
                        .immediate_send_with_tag(scope, &data[..], tag)
                })
                .collect();
            let out: Vec<Vec<u8>> = from
                .iter()
                .map(|&src| comm.process_at_rank(src as i32).receive_vec_with_tag::<u8>(tag).0)
                .collect();
            for p in pending {
                p.wait();
            }
            out
        }))
    }
}
