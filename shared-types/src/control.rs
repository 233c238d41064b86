//! `stack/control`: the launcher's request-response service (docs/architecture.md). `mole swap`,
//! `mole stop`, `mole status`, `mole fault` and `mole param` send a [`ControlRequest`]; the
//! running `mole up` answers with one [`ControlResponse`]. A setting changed while the stack runs
//! travels on to its process as a [`ParamChange`] on `stack/params`.

use crate::messages::{Header, NAME_LEN};
use crate::{Invalid, Message, read_name, within, write_name};
use bytemuck::{Pod, Zeroable};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// `ControlRequest::op`: replace `role` by the command in `argv`, while the rest runs.
pub const CONTROL_SWAP: u32 = 1;
/// `ControlRequest::op`: stop the stack as Ctrl-C would.
pub const CONTROL_STOP: u32 = 2;
/// `ControlRequest::op`: describe the stack in one line.
pub const CONTROL_STATUS: u32 = 3;
/// `ControlRequest::op`: inject the fault `argv` describes (`mole fault`,
/// `mole_types::FaultSpec::to_words`).
pub const CONTROL_FAULT: u32 = 4;
/// `ControlRequest::op`: list, get or set a setting of a running process (`mole param`); `argv`
/// is `list ROLE`, `get ROLE KEY` or `set ROLE KEY VALUE`.
pub const CONTROL_PARAM: u32 = 5;

/// Bytes for the NUL-separated words of a command.
pub const CONTROL_ARGV_LEN: usize = 2048;
/// Bytes for a directory path.
pub const CONTROL_PATH_LEN: usize = 1024;
/// Bytes for the answer's text (a sentence, or a role's settings for `mole param list`).
pub const CONTROL_TEXT_LEN: usize = 8192;

/// One request to the launcher.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.ControlRequest.v1")]
#[layout(size = 72 + CONTROL_PATH_LEN + CONTROL_ARGV_LEN)]
#[message(check = ControlRequest::check)]
pub struct ControlRequest {
    pub header: Header,
    /// `CONTROL_SWAP`, `CONTROL_STOP`, `CONTROL_STATUS`, `CONTROL_FAULT` or `CONTROL_PARAM`.
    pub op: u32,
    /// How many NUL-terminated words `argv` holds.
    pub n_args: u32,
    /// The role to swap, NUL-padded.
    pub role: [u8; NAME_LEN],
    /// The directory the command is run in (where `mole swap` was called), NUL-padded.
    pub cwd: [u8; CONTROL_PATH_LEN],
    /// The command, program first, each word NUL-terminated.
    pub argv: [u8; CONTROL_ARGV_LEN],
}

impl ControlRequest {
    /// An empty request for `op`.
    pub fn new(op: u32) -> Self {
        let mut request: Self = Zeroable::zeroed();
        request.op = op;
        request
    }

    /// Writes `words` NUL-terminated into `argv`; false when they do not fit or hold a NUL.
    pub fn set_argv<S: AsRef<str>>(&mut self, words: &[S]) -> bool {
        self.argv = [0; CONTROL_ARGV_LEN];
        let mut at = 0;
        for word in words {
            let bytes = word.as_ref().as_bytes();
            if bytes.contains(&0) || at + bytes.len() + 1 > CONTROL_ARGV_LEN {
                return false;
            }
            self.argv[at..at + bytes.len()].copy_from_slice(bytes);
            at += bytes.len() + 1;
        }
        self.n_args = words.len() as u32;
        true
    }

    /// A swap of `role` for the command `argv`, run in `cwd`; refused, saying which, when a
    /// part does not fit its field (or holds a NUL byte).
    pub fn swap<S: AsRef<str>>(role: &str, cwd: &str, argv: &[S]) -> Result<Self, String> {
        let mut request = Self::new(CONTROL_SWAP);
        write_name(&mut request.role, role);
        if read_name(&request.role) != role {
            return Err(format!("the role `{role}` is too long"));
        }
        write_name(&mut request.cwd, cwd);
        if read_name(&request.cwd) != cwd {
            return Err(format!(
                "the current directory's path is longer than {} bytes",
                request.cwd.len()
            ));
        }
        if argv.is_empty() {
            return Err("the command is empty".to_string());
        }
        if !request.set_argv(argv) {
            return Err(format!(
                "the command is longer than {} bytes or holds a NUL byte",
                request.argv.len()
            ));
        }
        Ok(request)
    }

    /// The words of `argv`, `None` when `n_args` does not match or a word is not UTF-8.
    pub fn argv(&self) -> Option<Vec<String>> {
        let mut words = Vec::with_capacity(self.n_args as usize);
        let mut rest = &self.argv[..];
        for _ in 0..self.n_args {
            let end = rest.iter().position(|&b| b == 0)?;
            words.push(std::str::from_utf8(&rest[..end]).ok()?.to_owned());
            rest = &rest[end + 1..];
        }
        Some(words)
    }
}

impl ControlRequest {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if !matches!(
            self.op,
            CONTROL_SWAP | CONTROL_STOP | CONTROL_STATUS | CONTROL_FAULT | CONTROL_PARAM
        ) {
            return Err(Invalid::UnknownCode("op"));
        }
        within("n_args", self.n_args, CONTROL_ARGV_LEN / 2)?;
        if matches!(self.op, CONTROL_SWAP | CONTROL_FAULT | CONTROL_PARAM)
            && (self.n_args == 0 || self.argv().is_none())
        {
            return Err(Invalid::OutOfRange("argv"));
        }
        Ok(())
    }
}

/// `ControlResponse::status`: done.
pub const CONTROL_OK: u32 = 0;
/// `ControlResponse::status`: refused, the request was wrong (an unknown role, a missing
/// program); nothing changed.
pub const CONTROL_REFUSED: u32 = 1;
/// `ControlResponse::status`: tried and failed (the new process died while starting); the old
/// process keeps running.
pub const CONTROL_FAILED: u32 = 2;

/// The launcher's answer.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.ControlResponse.v2")]
#[layout(size = 80 + CONTROL_TEXT_LEN)]
#[message(check = ControlResponse::check)]
pub struct ControlResponse {
    pub header: Header,
    /// `CONTROL_OK`, `CONTROL_REFUSED` or `CONTROL_FAILED`.
    pub status: u32,
    /// The new process's pid after a swap.
    pub pid: u32,
    /// The longest silence of the swapped role's output topic during the swap (ns).
    pub gap_ns: u64,
    /// The same topic's median interval between messages during the swap (ns).
    pub period_ns: u64,
    /// World steps whose tick never appeared on world/truth during the swap.
    pub steps_lost: u64,
    /// World steps published twice during the swap.
    pub steps_repeated: u64,
    /// The world's tick when the swap completed.
    pub tick: u64,
    /// What happened, in one sentence, NUL-padded UTF-8.
    pub text: [u8; CONTROL_TEXT_LEN],
}

impl ControlResponse {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if self.status > CONTROL_FAILED {
            return Err(Invalid::UnknownCode("status"));
        }
        Ok(())
    }
}

/// `ParamChange::state`: a request to a role's process (from the launcher, or a replay's
/// schedule).
pub const PARAM_REQUESTED: u32 = 1;
/// `ParamChange::state`: the process took the new value before step `apply_at`.
pub const PARAM_APPLIED: u32 = 2;
/// `ParamChange::state`: the process refused it (`text` says why); nothing changed.
pub const PARAM_REFUSED: u32 = 3;
/// Bytes for a setting's dotted key below its role.
pub const PARAM_KEY_LEN: usize = 96;
/// Bytes for a value as TOML writes it.
pub const PARAM_VALUE_LEN: usize = 96;
/// Bytes for the reason of a refusal.
pub const PARAM_TEXT_LEN: usize = 256;

/// `stack/params`: a setting of a running process changed (`mole param set`). The launcher
/// publishes the request; the role's process applies it at a step boundary and publishes the
/// outcome with the step, which the launcher answers with, the recorder keeps as an event and a
/// replay applies at the same step.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend, Message)]
#[type_name("mole.ParamChange.v1")]
#[layout(size = 56 + NAME_LEN + PARAM_KEY_LEN + PARAM_VALUE_LEN + PARAM_TEXT_LEN)]
#[message(check = ParamChange::check)]
pub struct ParamChange {
    pub header: Header,
    /// `PARAM_REQUESTED`, `PARAM_APPLIED` or `PARAM_REFUSED`.
    pub state: u32,
    /// The request's number in the run (the launcher's count); its outcome carries it too.
    pub request: u32,
    /// The step before which the value applies; 0 in a request: the next step the process
    /// handles.
    pub apply_at: u64,
    /// The launcher's stamp of the request (ns), so an outcome is matched to its request.
    pub requested_ns: u64,
    /// The role, NUL-padded.
    pub role: [u8; NAME_LEN],
    /// The key below the role, e.g. `dwa.critics.heading`, NUL-padded.
    pub key: [u8; PARAM_KEY_LEN],
    /// The value as TOML writes it, e.g. `0.4` or `"apf"`, NUL-padded.
    pub value: [u8; PARAM_VALUE_LEN],
    /// Why it was refused, NUL-padded UTF-8.
    pub text: [u8; PARAM_TEXT_LEN],
}

impl ParamChange {
    /// Whether the values make sense (`Message::validate`).
    fn check(&self) -> Result<(), Invalid> {
        if !matches!(self.state, PARAM_REQUESTED | PARAM_APPLIED | PARAM_REFUSED) {
            return Err(Invalid::UnknownCode("state"));
        }
        if self.role[0] == 0 || self.key[0] == 0 {
            return Err(Invalid::OutOfRange("role/key"));
        }
        for (field, bytes) in [
            ("role", &self.role[..]),
            ("key", &self.key[..]),
            ("value", &self.value[..]),
            ("text", &self.text[..]),
        ] {
            let end = bytes.iter().position(|b| *b == 0).unwrap_or(bytes.len());
            if std::str::from_utf8(&bytes[..end]).is_err() {
                return Err(Invalid::OutOfRange(field));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn argv_round_trips_and_refuses_what_does_not_fit() {
        let mut r: ControlRequest = Zeroable::zeroed();
        r.op = CONTROL_SWAP;
        assert!(r.set_argv(&["python3", "p y.py", ""]));
        assert_eq!(r.argv().unwrap(), ["python3", "p y.py", ""]);
        assert_eq!(r.validate(), Ok(()));
        assert!(!r.set_argv(&["a\0b"]));
        let long = "x".repeat(CONTROL_ARGV_LEN);
        assert!(!r.set_argv(&[long.as_str()]));
        r.argv = [b'x'; CONTROL_ARGV_LEN];
        r.n_args = 1;
        assert_eq!(r.argv(), None, "a word without its NUL");
        r.n_args = 0;
        assert_eq!(r.validate(), Err(Invalid::OutOfRange("argv")));
        r.op = 9;
        assert_eq!(r.validate(), Err(Invalid::UnknownCode("op")));
    }
}
