//! The radio session: a Noise `NNpsk0` handshake keyed with the pairing key, then sealed frames
//! (see [`protocol::auth`] for the wire layout). IO-free: randomness comes from an [`Entropy`]
//! the shell seeds (from the OS in production, from a number in tests), time is passed in.
//!
//! - Handshake: `Noise_NNpsk0_25519_ChaChaPoly_BLAKE2s` (the `snow` crate). The handheld sends
//!   [`HandshakeInit`] (`-> psk, e`), the onboard answers [`HandshakeReply`] (`<- e, ee`). Only a
//!   holder of the pairing key can produce an init the onboard answers; only the onboard that
//!   holds it can produce a reply the handheld accepts. The ephemeral-ephemeral DH gives each
//!   session fresh keys (forward secrecy), so an old session recorded off the air cannot be
//!   replayed into a new one. The prologue binds the protocol version and the key id.
//! - Transport: `snow`'s stateless transport state, i.e. ChaCha20-Poly1305 with the explicit
//!   64-bit nonce each sealed frame carries, one key per direction; received nonces go through a
//!   [`ReplayWindow`].
//! - Onboard: a bounded [`SessionTable`] of sessions for several paired handhelds. A new session
//!   is *unconfirmed* until its first sealed frame arrives (the proof that the handheld holds
//!   it); confirmed sessions are kept until [`MAX_SESSIONS`] forces out the least recently heard.
//!   A repeated init (the reply was lost) gets the same reply again; a replayed old init only
//!   creates an unconfirmed session nobody can use and disturbs no confirmed one.

use protocol::auth::{
    HANDSHAKE_MSG_LEN, Key, MAX_INNER_PAYLOAD_LEN, NONCE_LEN, Replay, ReplayWindow, SEAL_OVERHEAD,
    key_id,
};
use protocol::bounded::List;
use protocol::frame::{self, Flags, HEADER_LEN, Header, MAX_FRAME_LEN};
use protocol::radio::{HandshakeInit, HandshakeReply};
use protocol::{Message, ids};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha20Rng;
use snow::resolvers::{CryptoResolver, DefaultResolver};
use snow::types::{Cipher, Dh, Hash, Random};
use snow::{HandshakeState, StatelessTransportState};

/// The Noise protocol name.
pub const NOISE_PARAMS: &str = "Noise_NNpsk0_25519_ChaChaPoly_BLAKE2s";
/// Sessions the onboard keeps (confirmed and unconfirmed together).
pub const MAX_SESSIONS: usize = 8;

/// Randomness for handshakes: a ChaCha20 stream seeded once by the shell.
pub struct Entropy(ChaCha20Rng);

impl core::fmt::Debug for Entropy {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Entropy(..)")
    }
}

impl Entropy {
    /// A stream from a 32-byte seed.
    pub fn from_seed(seed: [u8; 32]) -> Self {
        Self(ChaCha20Rng::from_seed(seed))
    }

    /// A reproducible stream for tests and simulations.
    pub fn from_test_seed(seed: u64) -> Self {
        Self(ChaCha20Rng::seed_from_u64(seed))
    }

    /// A stream seeded by the operating system (getrandom).
    pub fn from_os() -> Result<Self, SessionError> {
        let mut seed = [0u8; 32];
        DefaultResolver
            .resolve_rng()
            .ok_or(SessionError::Noise("no system random source"))?
            .try_fill_bytes(&mut seed)
            .map_err(|_| SessionError::Noise("the system random source failed"))?;
        Ok(Self::from_seed(seed))
    }

    fn fork(&mut self) -> [u8; 32] {
        let mut seed = [0u8; 32];
        self.0.fill_bytes(&mut seed);
        seed
    }

    fn next_u16(&mut self) -> u16 {
        (self.0.next_u32() & 0xffff) as u16
    }
}

/// A resolver that takes its random numbers from a seed (the ephemeral keys) and everything else
/// from snow's pure-Rust default resolver.
struct SeededResolver([u8; 32]);

struct SeededRng(ChaCha20Rng);

impl Random for SeededRng {
    fn try_fill_bytes(&mut self, dest: &mut [u8]) -> Result<(), snow::Error> {
        self.0.fill_bytes(dest);
        Ok(())
    }
}

impl CryptoResolver for SeededResolver {
    fn resolve_rng(&self) -> Option<Box<dyn Random>> {
        Some(Box::new(SeededRng(ChaCha20Rng::from_seed(self.0))))
    }
    fn resolve_dh(&self, choice: &snow::params::DHChoice) -> Option<Box<dyn Dh>> {
        DefaultResolver.resolve_dh(choice)
    }
    fn resolve_hash(&self, choice: &snow::params::HashChoice) -> Option<Box<dyn Hash>> {
        DefaultResolver.resolve_hash(choice)
    }
    fn resolve_cipher(&self, choice: &snow::params::CipherChoice) -> Option<Box<dyn Cipher>> {
        DefaultResolver.resolve_cipher(choice)
    }
}

/// Why a session operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SessionError {
    /// The Noise library refused (bad message, wrong key, internal limit).
    #[error("noise: {0}")]
    Noise(&'static str),
    /// The init names a key this robot does not hold (never paired, or revoked).
    #[error("unknown pairing key id {0:08x}")]
    UnknownKey(u32),
    /// The frame is not a sealed frame of a known session.
    #[error("no session {0}")]
    UnknownSession(u16),
    /// The nonce was accepted before, or is older than the replay window.
    #[error("replayed or too old nonce {0}")]
    Replayed(u64),
    /// The frame did not authenticate (tampered, or another session's key).
    #[error("sealed frame did not authenticate")]
    BadTag,
    /// The sealed payload is too short or the inner frame too long.
    #[error("sealed frame of a wrong size")]
    Size,
}

fn prologue(key_id: u32) -> [u8; 24] {
    let mut p = [0u8; 24];
    p[..16].copy_from_slice(b"passangle radio ");
    p[16] = protocol::PROTOCOL_VERSION;
    p[17..21].copy_from_slice(&key_id.to_le_bytes());
    p
}

fn builder_state(
    key: &Key,
    seed: [u8; 32],
    initiator: bool,
) -> Result<HandshakeState, SessionError> {
    let params = NOISE_PARAMS
        .parse()
        .map_err(|_| SessionError::Noise("unsupported noise parameters"))?;
    let prologue = prologue(key_id(key));
    let b = snow::Builder::with_resolver(params, Box::new(SeededResolver(seed)))
        .psk(0, &key.0)
        .and_then(|b| b.prologue(&prologue))
        .map_err(|_| SessionError::Noise("cannot configure the handshake"))?;
    if initiator {
        b.build_initiator()
    } else {
        b.build_responder()
    }
    .map_err(|_| SessionError::Noise("cannot build the handshake"))
}

fn encode_outer<M: Message>(msg: &M, seq: u16) -> Option<Vec<u8>> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = msg.encode_frame(seq, Flags::NONE, &mut buf).ok()?;
    Some(buf[..n].to_vec())
}

/// One established session end: transport keys, the next nonce to send, the replay window.
pub struct Session {
    id: u16,
    key_id: u32,
    transport: StatelessTransportState,
    next_nonce: u64,
    window: ReplayWindow,
}

impl core::fmt::Debug for Session {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Session")
            .field("id", &self.id)
            .field("key_id", &format_args!("{:08x}", self.key_id))
            .field("next_nonce", &self.next_nonce)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// The session id sealed frames carry.
    pub fn id(&self) -> u16 {
        self.id
    }

    /// Id of the pairing key that opened it.
    pub fn key_id(&self) -> u32 {
        self.key_id
    }

    /// Seals an inner frame (header and payload, no CRC) into a whole outer frame on the wire
    /// (COBS and delimiter included). `None` if the inner frame is too long.
    pub fn seal(&mut self, inner: &[u8]) -> Option<Vec<u8>> {
        if inner.len() < HEADER_LEN || inner.len() > HEADER_LEN + MAX_INNER_PAYLOAD_LEN {
            return None;
        }
        let nonce = self.next_nonce;
        self.next_nonce = nonce.checked_add(1)?;
        let mut payload = vec![0u8; NONCE_LEN + inner.len() + SEAL_OVERHEAD - NONCE_LEN];
        payload[..NONCE_LEN].copy_from_slice(&nonce.to_le_bytes());
        let n = self
            .transport
            .write_message(nonce, inner, &mut payload[NONCE_LEN..])
            .ok()?;
        payload.truncate(NONCE_LEN + n);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let len = frame::encode_raw(
            Header::new(ids::SEALED, self.id, Flags::NONE),
            &payload,
            &mut buf,
        )
        .ok()?;
        Some(buf[..len].to_vec())
    }

    /// Opens a sealed payload (nonce and ciphertext): the inner frame's header and payload.
    pub fn open(&mut self, sealed: &[u8]) -> Result<(Header, Vec<u8>), SessionError> {
        if sealed.len() < NONCE_LEN + HEADER_LEN + SEAL_OVERHEAD - NONCE_LEN {
            return Err(SessionError::Size);
        }
        let mut nonce_bytes = [0u8; NONCE_LEN];
        nonce_bytes.copy_from_slice(&sealed[..NONCE_LEN]);
        let nonce = u64::from_le_bytes(nonce_bytes);
        if self.window.check(nonce) != Replay::Fresh {
            return Err(SessionError::Replayed(nonce));
        }
        let ciphertext = &sealed[NONCE_LEN..];
        let mut plain = vec![0u8; ciphertext.len()];
        let n = self
            .transport
            .read_message(nonce, ciphertext, &mut plain)
            .map_err(|_| SessionError::BadTag)?;
        self.window.mark(nonce);
        plain.truncate(n);
        let mut header = [0u8; HEADER_LEN];
        header.copy_from_slice(&plain[..HEADER_LEN]);
        let payload = plain[HEADER_LEN..].to_vec();
        Ok((Header::from_bytes(header), payload))
    }
}

/// The handheld's side of a handshake in progress.
pub struct Initiator {
    key_id: u32,
    state: HandshakeState,
    init_frame: Vec<u8>,
}

impl core::fmt::Debug for Initiator {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Initiator(key {:08x})", self.key_id)
    }
}

impl Initiator {
    /// Starts a handshake with `key`.
    pub fn new(key: &Key, entropy: &mut Entropy) -> Result<Self, SessionError> {
        let mut state = builder_state(key, entropy.fork(), true)?;
        let mut msg = [0u8; 64];
        let n = state
            .write_message(&[], &mut msg)
            .map_err(|_| SessionError::Noise("cannot write the handshake"))?;
        let key_id = key_id(key);
        let init = HandshakeInit {
            key_id,
            noise: List::from_slice(&msg[..n]).ok_or(SessionError::Size)?,
        };
        let init_frame = encode_outer(&init, 0).ok_or(SessionError::Size)?;
        Ok(Self {
            key_id,
            state,
            init_frame,
        })
    }

    /// The init frame to send (again, as long as no reply came).
    pub fn init_frame(&self) -> &[u8] {
        &self.init_frame
    }

    /// Completes the handshake with the onboard's reply. On an error the handshake state is
    /// spent (Noise mixes the reply into it before the check): start a new [`Initiator`].
    pub fn finish(mut self, reply: &HandshakeReply) -> Result<Session, SessionError> {
        if reply.key_id != self.key_id {
            return Err(SessionError::UnknownKey(reply.key_id));
        }
        let mut payload = [0u8; 64];
        self.state
            .read_message(reply.noise.as_slice(), &mut payload)
            .map_err(|_| SessionError::BadTag)?;
        let transport = self
            .state
            .into_stateless_transport_mode()
            .map_err(|_| SessionError::Noise("handshake did not complete"))?;
        Ok(Session {
            id: reply.session,
            key_id: self.key_id,
            transport,
            next_nonce: 0,
            window: ReplayWindow::new(),
        })
    }
}

struct Slot {
    session: Session,
    /// The init that created it and the reply frame, to answer a repeated init identically.
    init_noise: [u8; HANDSHAKE_MSG_LEN],
    reply_frame: Vec<u8>,
    confirmed: bool,
    last_rx_us: u64,
}

/// What [`SessionTable::on_init`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InitOutcome {
    /// A new unconfirmed session: send the reply.
    New {
        /// Its id.
        session: u16,
        /// The reply frame.
        reply: Vec<u8>,
    },
    /// A repeated init: send the same reply again.
    Repeat {
        /// The reply frame.
        reply: Vec<u8>,
    },
}

/// The onboard's sessions (see the module docs).
pub struct SessionTable {
    keys: Vec<(u32, Key)>,
    slots: Vec<Slot>,
    entropy: Entropy,
    next_id: u16,
}

impl core::fmt::Debug for SessionTable {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SessionTable")
            .field("keys", &self.keys.len())
            .field("sessions", &self.slots.len())
            .finish_non_exhaustive()
    }
}

impl SessionTable {
    /// A table for the paired keys.
    pub fn new(keys: Vec<Key>, mut entropy: Entropy) -> Self {
        let next_id = entropy.next_u16();
        Self {
            keys: keys.into_iter().map(|k| (key_id(&k), k)).collect(),
            slots: Vec::new(),
            entropy,
            next_id,
        }
    }

    /// Sessions held (confirmed or not).
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether no session is held.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Whether `session` is held and confirmed.
    pub fn is_confirmed(&self, session: u16) -> bool {
        self.slots
            .iter()
            .any(|s| s.session.id == session && s.confirmed)
    }

    /// Key id of a held session.
    pub fn key_of(&self, session: u16) -> Option<u32> {
        self.slots
            .iter()
            .find(|s| s.session.id == session)
            .map(|s| s.session.key_id)
    }

    /// Answers a handshake init (see the module docs).
    pub fn on_init(&mut self, init: &HandshakeInit) -> Result<InitOutcome, SessionError> {
        let noise = init.noise.as_slice();
        if noise.len() != HANDSHAKE_MSG_LEN {
            return Err(SessionError::Size);
        }
        if let Some(s) = self
            .slots
            .iter()
            .find(|s| s.session.key_id == init.key_id && s.init_noise[..] == *noise)
        {
            if s.confirmed {
                // The handheld has this session: a late copy of its init changes nothing.
                return Err(SessionError::Replayed(0));
            }
            return Ok(InitOutcome::Repeat {
                reply: s.reply_frame.clone(),
            });
        }
        let key = self
            .keys
            .iter()
            .find(|(id, _)| *id == init.key_id)
            .map(|(_, k)| k.clone())
            .ok_or(SessionError::UnknownKey(init.key_id))?;
        let mut state = builder_state(&key, self.entropy.fork(), false)?;
        let mut payload = [0u8; 64];
        state
            .read_message(noise, &mut payload)
            .map_err(|_| SessionError::BadTag)?;
        let mut msg = [0u8; 64];
        let n = state
            .write_message(&[], &mut msg)
            .map_err(|_| SessionError::Noise("cannot write the reply"))?;
        let transport = state
            .into_stateless_transport_mode()
            .map_err(|_| SessionError::Noise("handshake did not complete"))?;
        let id = self.fresh_id();
        let reply = HandshakeReply {
            key_id: init.key_id,
            session: id,
            noise: List::from_slice(&msg[..n]).ok_or(SessionError::Size)?,
        };
        let reply_frame = encode_outer(&reply, 0).ok_or(SessionError::Size)?;
        let mut init_noise = [0u8; HANDSHAKE_MSG_LEN];
        init_noise.copy_from_slice(noise);
        // One unconfirmed session per key: a newer init replaces an older unconfirmed one.
        self.slots
            .retain(|s| s.confirmed || s.session.key_id != init.key_id);
        if self.slots.len() >= MAX_SESSIONS {
            // Out goes an unconfirmed session if any, else the least recently heard.
            let victim = self
                .slots
                .iter()
                .enumerate()
                .min_by_key(|(_, s)| (s.confirmed, s.last_rx_us))
                .map(|(i, _)| i);
            if let Some(i) = victim {
                self.slots.swap_remove(i);
            }
        }
        self.slots.push(Slot {
            session: Session {
                id,
                key_id: init.key_id,
                transport,
                next_nonce: 0,
                window: ReplayWindow::new(),
            },
            init_noise,
            reply_frame: reply_frame.clone(),
            confirmed: false,
            last_rx_us: 0,
        });
        Ok(InitOutcome::New {
            session: id,
            reply: reply_frame,
        })
    }

    fn fresh_id(&mut self) -> u16 {
        loop {
            let id = self.next_id;
            self.next_id = self.next_id.wrapping_add(1);
            if !self.slots.iter().any(|s| s.session.id == id) {
                return id;
            }
        }
    }

    /// Opens a sealed frame of `session`; confirms the session on its first frame.
    pub fn open(
        &mut self,
        now_us: u64,
        session: u16,
        sealed: &[u8],
    ) -> Result<(Header, Vec<u8>), SessionError> {
        let slot = self
            .slots
            .iter_mut()
            .find(|s| s.session.id == session)
            .ok_or(SessionError::UnknownSession(session))?;
        let opened = slot.session.open(sealed)?;
        slot.confirmed = true;
        slot.last_rx_us = now_us;
        Ok(opened)
    }

    /// Seals an inner frame for `session` (only a confirmed one: the handheld has proved it holds
    /// it). `None` when there is no such session.
    pub fn seal(&mut self, session: u16, inner: &[u8]) -> Option<Vec<u8>> {
        self.slots
            .iter_mut()
            .find(|s| s.session.id == session && s.confirmed)?
            .session
            .seal(inner)
    }
}
