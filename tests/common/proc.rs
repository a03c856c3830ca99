//! Running programs in the background for the live tests: polled waits against a deadline, and
//! [`Proc`], a child whose output is collected as it comes.

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;
use std::io::Read;
use std::process::{Child, ChildStdin, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

/// Only reached when something is broken (a loaded 2-core CI machine is slow, not stuck).
pub const DEADLINE: Duration = Duration::from_secs(60);
/// How often conditions are looked at again.
pub const POLL: Duration = Duration::from_millis(10);

/// Wait for `cond` until the deadline; panics with `what` (and `ctx()`) when it never holds.
pub fn wait_for(what: &str, ctx: impl Fn() -> String, mut cond: impl FnMut() -> bool) {
    let t0 = Instant::now();
    while !cond() {
        assert!(
            t0.elapsed() < DEADLINE,
            "timed out waiting for {what}\n{}",
            ctx()
        );
        thread::sleep(POLL);
    }
}

/// The lock, also when a panicking thread poisoned it (what it guards is text, still usable).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A running program, its standard output and error collected as they come; killed if still
/// running when dropped (a failing test leaves nothing behind).
pub struct Proc {
    name: String,
    child: Child,
    out: Arc<Mutex<String>>,
    err: Arc<Mutex<String>>,
    readers: Vec<JoinHandle<()>>,
    status: Option<ExitStatus>,
}

/// Collect what `pipe` gives into `sink` as it comes.
fn collect(mut pipe: impl Read + Send + 'static, sink: Arc<Mutex<String>>) -> JoinHandle<()> {
    thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = pipe.read(&mut buf) {
            if n == 0 {
                break;
            }
            lock(&sink).push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    })
}

impl Proc {
    /// Start `cmd` (standard input empty), called `name` in failure messages.
    pub fn spawn(mut cmd: Command, name: &str) -> Proc {
        cmd.stdin(Stdio::null());
        Proc::start(cmd, name)
    }

    /// Start `aptscope ARGS` reading a pipe the test writes: the process and the pipe's end.
    pub fn aptscope_piped(args: &[&str]) -> (Proc, ChildStdin) {
        let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"));
        c.args(args).stdin(Stdio::piped());
        let mut p = Proc::start(c, &format!("aptscope {}", args.join(" ")));
        let stdin = p.child.stdin.take().expect("stdin");
        (p, stdin)
    }

    fn start(mut cmd: Command, name: &str) -> Proc {
        let mut child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("run {name}: {e}"));
        let (out, err) = <(Arc<Mutex<String>>, Arc<Mutex<String>>)>::default();
        let readers = vec![
            collect(child.stdout.take().expect("stdout"), out.clone()),
            collect(child.stderr.take().expect("stderr"), err.clone()),
        ];
        Proc {
            name: name.into(),
            child,
            out,
            err,
            readers,
            status: None,
        }
    }

    /// Start `aptscope ARGS`, named after its first two arguments.
    pub fn aptscope<S: AsRef<str>>(args: &[S]) -> Proc {
        let args: Vec<&str> = args.iter().map(AsRef::as_ref).collect();
        let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"));
        c.args(&args);
        Proc::spawn(
            c,
            &format!("aptscope {}", args[..2.min(args.len())].join(" ")),
        )
    }

    /// Its process id.
    pub fn pid(&self) -> Pid {
        Pid::from_raw(self.child.id() as i32)
    }

    /// Send it `sig`.
    pub fn signal(&self, sig: Signal) {
        kill(self.pid(), sig).expect("send signal");
    }

    /// What it wrote on standard output so far.
    pub fn stdout(&self) -> String {
        lock(&self.out).clone()
    }

    /// What it wrote on standard error so far.
    pub fn stderr(&self) -> String {
        lock(&self.err).clone()
    }

    /// Its name and both outputs so far, for failure messages.
    pub fn both(&self) -> String {
        format!(
            "{}: stdout:\n{}\nstderr:\n{}",
            self.name,
            self.stdout(),
            self.stderr()
        )
    }

    /// Whether it is still running.
    pub fn running(&mut self) -> bool {
        self.status.is_none() && matches!(self.child.try_wait(), Ok(None))
    }

    /// Wait until its standard error contains `s`.
    pub fn wait_stderr(&self, s: &str) {
        wait_for(
            &format!("`{s}` from {}", self.name),
            || self.stderr(),
            || self.stderr().contains(s),
        );
    }

    /// Wait for it to exit (failing, not hanging, when it does not), then for the rest of its
    /// output.
    pub fn wait_exit(&mut self) -> ExitStatus {
        if let Some(s) = self.status {
            return s;
        }
        let t0 = Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().expect("try_wait") {
                break s;
            }
            if t0.elapsed() > DEADLINE {
                let _ = self.child.kill();
                let _ = self.child.wait();
                panic!("{} did not exit\n{}", self.name, self.both());
            }
            thread::sleep(POLL);
        };
        self.status = Some(status);
        for r in self.readers.drain(..) {
            let _ = r.join();
        }
        status
    }

    /// SIGINT, then a clean exit (failing when it is not).
    pub fn interrupt(&mut self) {
        self.signal(Signal::SIGINT);
        let st = self.wait_exit();
        assert!(st.success(), "{st}\n{}", self.both());
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if self.running() {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}
