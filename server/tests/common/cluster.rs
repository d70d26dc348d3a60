//! The distributed shape's engines for tests, started on loopback by the test itself:
//! PostgreSQL from the system's packages (`initdb`/`pg_ctl` in a temporary folder, as the
//! `postgres` user when run as root) and an S3-compatible server (`moto_server`, PyPI's
//! `moto[server]`). `.ci/run` installs both; where one is missing the test skips with a
//! message. Also: `bspvt-server worker` processes and SQL through `psql`.

#![allow(dead_code)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use super::common::BIN;

/// CPU seconds (user + system) of process `pid`, and of its children it has reaped.
pub fn cpu_s(pid: u32) -> f64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0.0))
        .collect();
    // utime, stime, cutime, cstime are fields 14..=17, i.e. 11..=14 after the name.
    let ticks: f64 = f.get(11..15).map_or(0.0, |v| v.iter().sum());
    ticks / 100.0
}

/// A free loopback port (bound then released).
pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn wait_port(port: u16, timeout: Duration) -> bool {
    let t0 = Instant::now();
    while t0.elapsed() < timeout {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    false
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

/// The PostgreSQL server binaries (`initdb`, `pg_ctl`), newest version first.
fn pg_bin() -> Option<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .flatten()
        .map(|e| e.path().join("bin"))
        .filter(|b| b.join("pg_ctl").exists() && b.join("initdb").exists())
        .collect();
    dirs.sort();
    dirs.pop()
}

/// A PostgreSQL server in a temporary folder.
pub struct Postgres {
    bin: PathBuf,
    data: PathBuf,
    pub port: u16,
    pub url: String,
    as_postgres: bool,
    log: PathBuf,
    /// `fsync` (off for tests: faster, and no test cuts the power); takes effect at the next
    /// (re)start.
    pub fsync: bool,
}

impl Postgres {
    /// Starts one, or says why not (the test then skips).
    pub fn start(dir: &Path) -> Result<Postgres, String> {
        let bin = pg_bin().ok_or("PostgreSQL is not installed (/usr/lib/postgresql/*/bin)")?;
        let as_postgres = is_root();
        let data = dir.join("pgdata");
        std::fs::create_dir_all(&data).map_err(|e| e.to_string())?;
        if as_postgres {
            // The server refuses to run as root: the folder and its parents must be the
            // postgres user's to use.
            let _ = Command::new("chown")
                .args(["-R", "postgres"])
                .arg(dir)
                .status();
            let _ = Command::new("chmod").args(["755"]).arg(dir).status();
        }
        let pg = Postgres {
            port: free_port(),
            url: String::new(),
            log: dir.join("postgres.log"),
            bin,
            data,
            as_postgres,
            fsync: false,
        };
        let out = pg
            .cmd("initdb")
            .args(["-A", "trust", "-U", "postgres", "-E", "UTF8", "-D"])
            .arg(&pg.data)
            .output()
            .map_err(|e| format!("cannot run initdb: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "initdb failed: {}",
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        let mut pg = pg;
        pg.url = format!("postgres://postgres@127.0.0.1:{}/postgres", pg.port);
        pg.pg_ctl(&["start"])?;
        Ok(pg)
    }

    fn cmd(&self, tool: &str) -> Command {
        let path = self.bin.join(tool);
        if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(path);
            c
        } else {
            Command::new(path)
        }
    }

    fn pg_ctl(&self, what: &[&str]) -> Result<(), String> {
        let opts = format!(
            "-p {} -c listen_addresses=127.0.0.1 -k {} -c fsync={} -c max_connections=200",
            self.port,
            self.data.display(),
            if self.fsync { "on" } else { "off" }
        );
        let out = self
            .cmd("pg_ctl")
            .arg("-D")
            .arg(&self.data)
            .args(["-l"])
            .arg(&self.log)
            .args(["-o", &opts, "-w", "-t", "60"])
            .args(what)
            .output()
            .map_err(|e| format!("cannot run pg_ctl: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "pg_ctl {what:?} failed: {}{}",
                String::from_utf8_lossy(&out.stderr),
                std::fs::read_to_string(&self.log).unwrap_or_default()
            ));
        }
        Ok(())
    }

    /// Stops the server at once (as a crash would: `-m immediate`) and starts it again.
    pub fn restart(&self) {
        self.pg_ctl(&["-m", "immediate", "stop"])
            .expect("stop PostgreSQL");
        self.pg_ctl(&["start"]).expect("start PostgreSQL again");
    }

    /// CPU seconds of the server: the postmaster and the backends it has reaped (a backend
    /// is reaped when its connection closes).
    pub fn cpu_s(&self) -> f64 {
        let pid = std::fs::read_to_string(self.data.join("postmaster.pid"))
            .ok()
            .and_then(|s| s.lines().next().and_then(|l| l.trim().parse().ok()))
            .unwrap_or(0);
        cpu_s(pid)
    }

    /// Runs one SQL query with `psql` and returns its unaligned output.
    pub fn sql(&self, q: &str) -> String {
        let psql = self.bin.join("psql");
        let psql = if psql.exists() {
            psql
        } else {
            PathBuf::from("psql")
        };
        let out = Command::new(psql)
            .args(["-X", "-A", "-t", "-q", "-d", &self.url, "-c", q])
            .output()
            .expect("run psql");
        assert!(
            out.status.success(),
            "psql {q:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }

    /// [`Postgres::sql`] as a number.
    pub fn number(&self, q: &str) -> i64 {
        let s = self.sql(q);
        s.parse()
            .unwrap_or_else(|_| panic!("{q:?} answered {s:?}, not a number"))
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        let _ = self.pg_ctl(&["-m", "immediate", "stop"]);
    }
}

/// An S3-compatible server (`moto_server`) with one bucket.
pub struct S3 {
    pub child: Child,
    pub port: u16,
    /// The port clients are pointed at (`env`): the server's, or a [`FaultyProxy`]'s.
    pub endpoint: u16,
    pub bucket: String,
}

impl S3 {
    pub fn start(dir: &Path) -> Result<S3, String> {
        let port = free_port();
        let log = std::fs::File::create(dir.join("s3.log")).map_err(|e| e.to_string())?;
        let child = Command::new("moto_server")
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::from(log))
            .spawn()
            .map_err(|e| format!("cannot start moto_server (pip install 'moto[server]'): {e}"))?;
        let mut s3 = S3 {
            child,
            port,
            endpoint: port,
            bucket: "bspvt-test".into(),
        };
        if !wait_port(port, Duration::from_secs(60)) {
            return Err("moto_server did not listen within 60 s".into());
        }
        let a = super::common::agent();
        let r = a
            .put(format!("http://127.0.0.1:{port}/{}", s3.bucket))
            .send_empty()
            .map_err(|e| format!("cannot create the bucket: {e}"))?;
        if !r.status().is_success() {
            return Err(format!("creating the bucket answered {}", r.status()));
        }
        s3.bucket = s3.bucket.clone();
        Ok(s3)
    }

    /// The AWS variables that point a client at this server.
    pub fn env(&self) -> Vec<(String, String)> {
        vec![
            ("AWS_ACCESS_KEY_ID".into(), "test".into()),
            ("AWS_SECRET_ACCESS_KEY".into(), "test".into()),
            ("AWS_REGION".into(), "us-east-1".into()),
            (
                "AWS_ENDPOINT_URL".into(),
                format!("http://127.0.0.1:{}", self.endpoint),
            ),
            ("AWS_ALLOW_HTTP".into(), "true".into()),
        ]
    }

    pub fn url(&self, prefix: &str) -> String {
        format!("s3://{}/{prefix}", self.bucket)
    }
}

impl Drop for S3 {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A TCP proxy in front of the S3 server that fails on purpose: it passes connections
/// through, or (failing) cuts every open connection and answers each new request `503 Slow
/// Down` with S3's `SlowDown` error, as a throttled or overloaded S3 does, or (after
/// [`FaultyProxy::internal_errors`]) `500` with S3's `InternalError`.
pub struct FaultyProxy {
    pub port: u16,
    failing: Arc<AtomicBool>,
    internal: Arc<AtomicBool>,
    refused: Arc<AtomicU64>,
    internal_answered: Arc<AtomicU64>,
    open: Arc<Mutex<Vec<TcpStream>>>,
    stop: Arc<AtomicBool>,
}

impl FaultyProxy {
    pub fn start(upstream: u16) -> FaultyProxy {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind the proxy");
        let port = listener.local_addr().expect("address").port();
        let p = FaultyProxy {
            port,
            failing: Default::default(),
            internal: Default::default(),
            refused: Default::default(),
            internal_answered: Default::default(),
            open: Default::default(),
            stop: Default::default(),
        };
        let (failing, internal, refused, internal_answered, open, stop) = (
            p.failing.clone(),
            p.internal.clone(),
            p.refused.clone(),
            p.internal_answered.clone(),
            p.open.clone(),
            p.stop.clone(),
        );
        std::thread::spawn(move || {
            for client in listener.incoming() {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                let Ok(client) = client else { continue };
                if failing.load(Ordering::Relaxed) {
                    refused.fetch_add(1, Ordering::Relaxed);
                    let internal = internal.load(Ordering::Relaxed);
                    if internal {
                        internal_answered.fetch_add(1, Ordering::Relaxed);
                    }
                    std::thread::spawn(move || answer_error(client, internal));
                    continue;
                }
                let Ok(server) = TcpStream::connect(("127.0.0.1", upstream)) else {
                    continue;
                };
                if let (Ok(c), Ok(s)) = (client.try_clone(), server.try_clone()) {
                    open.lock().unwrap().extend([c, s]);
                }
                pipe(&client, &server);
                pipe(&server, &client);
            }
        });
        p
    }

    /// Starts or stops failing; starting cuts every connection open now.
    pub fn fail(&self, on: bool) {
        self.failing.store(on, Ordering::Relaxed);
        if on {
            for s in self.open.lock().unwrap().drain(..) {
                let _ = s.shutdown(std::net::Shutdown::Both);
            }
        }
    }

    /// Fails with `500 InternalError` instead of `503 SlowDown` from now on.
    pub fn internal_errors(&self) {
        self.internal.store(true, Ordering::Relaxed);
    }

    /// Connections answered `500` so far.
    pub fn internal_answered(&self) -> u64 {
        self.internal_answered.load(Ordering::Relaxed)
    }

    /// Connections answered an error so far.
    pub fn refused(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }
}

impl Drop for FaultyProxy {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = TcpStream::connect(("127.0.0.1", self.port));
        self.fail(true);
    }
}

/// Copies `from` into `to` on a thread until either closes.
fn pipe(from: &TcpStream, to: &TcpStream) {
    let (Ok(mut from), Ok(mut to)) = (from.try_clone(), to.try_clone()) else {
        return;
    };
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut from, &mut to);
        let _ = to.shutdown(std::net::Shutdown::Write);
    });
}

/// Reads a request's head and answers S3's throttling error (or `internal`: its internal
/// error), then closes.
fn answer_error(mut c: TcpStream, internal: bool) {
    let _ = c.set_read_timeout(Some(Duration::from_secs(5)));
    let mut head = Vec::new();
    let mut b = [0u8; 4096];
    while !head.windows(4).any(|w| w == b"\r\n\r\n") {
        match c.read(&mut b) {
            Ok(n) if n > 0 => head.extend_from_slice(&b[..n]),
            _ => return,
        }
    }
    let (status, code, message) = if internal {
        (
            "500 Internal Server Error",
            "InternalError",
            "We encountered an internal error. Please try again.",
        )
    } else {
        (
            "503 Slow Down",
            "SlowDown",
            "Please reduce your request rate.",
        )
    };
    let body = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?><Error><Code>{code}</Code>\
         <Message>{message}</Message></Error>"
    );
    let _ = write!(
        c,
        "HTTP/1.1 {status}\r\nContent-Type: application/xml\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n{body}",
        body.len()
    );
    let _ = c.shutdown(std::net::Shutdown::Both);
}

/// Both engines, or `None` after printing why the test is skipped.
pub fn engines(dir: &Path, test: &str) -> Option<(Postgres, S3)> {
    let pg = match Postgres::start(dir) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("SKIPPED {test}: no PostgreSQL ({e}); .ci/run installs it");
            return None;
        }
    };
    match S3::start(dir) {
        Ok(s3) => Some((pg, s3)),
        Err(e) => {
            eprintln!("SKIPPED {test}: no S3-compatible server ({e}); .ci/run installs it");
            None
        }
    }
}

/// A `bspvt-server worker` process.
pub struct Worker {
    pub child: Child,
    pub id: String,
    pub log: PathBuf,
}

impl Worker {
    pub fn start(
        dir: &Path,
        id: &str,
        pg: &Postgres,
        s3: &S3,
        prefix: &str,
        extra: &[&str],
    ) -> Worker {
        Worker::spawn(dir, id, &pg.url, &s3.env(), &s3.url(prefix), extra, None)
    }

    /// A worker in `ns`, reaching PostgreSQL and the S3 server through its forwards.
    pub fn start_in(
        ns: &Netns,
        dir: &Path,
        id: &str,
        (pg, pg_port): (&Postgres, u16),
        (s3, s3_port): (&S3, u16),
        prefix: &str,
        extra: &[&str],
    ) -> Worker {
        let url = pg.url.replace(
            &format!("127.0.0.1:{}", pg.port),
            &format!("{}:{pg_port}", ns.host_ip),
        );
        let mut env = s3.env();
        for (k, v) in &mut env {
            if k == "AWS_ENDPOINT_URL" {
                *v = format!("http://{}:{s3_port}", ns.host_ip);
            }
        }
        Worker::spawn(dir, id, &url, &env, &s3.url(prefix), extra, Some(ns))
    }

    fn spawn(
        dir: &Path,
        id: &str,
        database: &str,
        env: &[(String, String)],
        store: &str,
        extra: &[&str],
        ns: Option<&Netns>,
    ) -> Worker {
        let log = dir.join(format!("{id}.log"));
        let mut cmd = match ns {
            Some(ns) => {
                let mut c = Command::new("ip");
                c.args(["netns", "exec", &ns.name, BIN]);
                c
            }
            None => Command::new(BIN),
        };
        let mut child = cmd
            .args([
                "worker",
                "--database",
                database,
                "--store",
                store,
                "--id",
                id,
            ])
            .args(extra)
            .envs(env.iter().cloned())
            // Its own folder: working directory, temporaries and log.
            .current_dir(dir)
            .env("TMPDIR", dir)
            .env("RUST_LOG", "info,bspvt_server::service::cluster=debug")
            .stdout(Stdio::piped())
            .stderr(Stdio::from(
                std::fs::File::create(&log).expect("worker log"),
            ))
            .spawn()
            .expect("start a worker");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("stdout");
        let _ = BufReader::new(stdout).read_line(&mut line);
        assert!(
            line.starts_with("worker "),
            "worker {id} did not start: {line:?}\n{}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        Worker {
            child,
            id: id.to_string(),
            log,
        }
    }

    pub fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// SIGKILL, then reap.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Sends a signal (`STOP`, `CONT`, `TERM`).
    pub fn signal(&self, sig: &str) {
        let st = Command::new("kill")
            .args([&format!("-{sig}"), &self.child.id().to_string()])
            .status()
            .expect("run kill");
        assert!(st.success(), "kill -{sig} failed");
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.signal_quiet();
        self.kill();
    }
}

impl Worker {
    fn signal_quiet(&self) {
        let _ = Command::new("kill")
            .args(["-CONT", &self.child.id().to_string()])
            .stderr(Stdio::null())
            .status();
    }
}

/// A network namespace of its own for a worker: joined to this one by a veth pair (this side
/// `host_ip`, the namespace's `.2`), with TCP forwards on `host_ip` to services on this
/// side's loopback. [`Netns::cut`] drops every packet in the namespace (iptables), as a pulled
/// cable or a partitioned switch does: no reset, connections hang until their own timeouts.
/// Needs root, iproute2 and iptables; [`Netns::create`] says why not otherwise.
pub struct Netns {
    pub name: String,
    host_if: String,
    ns_if: String,
    pub host_ip: String,
    stop: Arc<AtomicBool>,
}

fn run(args: &[&str]) -> Result<(), String> {
    let out = Command::new(args[0])
        .args(&args[1..])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", args[0]))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Netns {
    pub fn create() -> Result<Netns, String> {
        if !is_root() {
            return Err("not root".into());
        }
        // Unique per test process: interface names hold at most 15 bytes.
        let n = std::process::id() % 250;
        let ns = Netns {
            name: format!("bspvt-w{n}"),
            host_if: format!("bspvt{n}h"),
            ns_if: format!("bspvt{n}n"),
            host_ip: format!("10.231.{n}.1"),
            stop: Default::default(),
        };
        let _ = run(&["ip", "netns", "del", &ns.name]);
        let _ = run(&["ip", "link", "del", &ns.host_if]);
        let ns_ip = format!("10.231.{n}.2/30");
        let host_cidr = format!("{}/30", ns.host_ip);
        let exec = |args: &[&str]| {
            let mut a = vec!["ip", "netns", "exec", &ns.name];
            a.extend_from_slice(args);
            run(&a)
        };
        run(&["ip", "netns", "add", &ns.name])?;
        run(&[
            "ip",
            "link",
            "add",
            &ns.host_if,
            "type",
            "veth",
            "peer",
            "name",
            &ns.ns_if,
        ])?;
        run(&["ip", "link", "set", &ns.ns_if, "netns", &ns.name])?;
        run(&["ip", "addr", "add", &host_cidr, "dev", &ns.host_if])?;
        run(&["ip", "link", "set", &ns.host_if, "up"])?;
        exec(&["ip", "addr", "add", &ns_ip, "dev", &ns.ns_if])?;
        exec(&["ip", "link", "set", &ns.ns_if, "up"])?;
        exec(&["ip", "link", "set", "lo", "up"])?;
        exec(&["iptables", "-S"])?;
        Ok(ns)
    }

    /// A port on `host_ip` that forwards to `upstream` on this side's loopback.
    pub fn forward(&self, upstream: u16) -> u16 {
        let listener = TcpListener::bind((self.host_ip.as_str(), 0)).expect("bind a forward");
        let port = listener.local_addr().expect("address").port();
        let stop = self.stop.clone();
        std::thread::spawn(move || {
            for client in listener.incoming() {
                if stop.load(Ordering::Relaxed) {
                    break;
                }
                let Ok(client) = client else { continue };
                let Ok(server) = TcpStream::connect(("127.0.0.1", upstream)) else {
                    continue;
                };
                pipe(&client, &server);
                pipe(&server, &client);
            }
        });
        port
    }

    /// Drops every packet in and out of the namespace (`on`), or lets them through again.
    pub fn cut(&self, on: bool) {
        let mut args = vec!["ip", "netns", "exec", &self.name, "iptables"];
        if on {
            for rule in [["-A", "INPUT", "-i"], ["-A", "OUTPUT", "-o"]] {
                let mut a = args.clone();
                a.extend_from_slice(&rule);
                a.extend_from_slice(&[&self.ns_if, "-j", "DROP"]);
                run(&a).expect("iptables DROP");
            }
        } else {
            args.push("-F");
            run(&args).expect("iptables -F");
        }
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = run(&["ip", "netns", "del", &self.name]);
        let _ = run(&["ip", "link", "del", &self.host_if]);
    }
}
