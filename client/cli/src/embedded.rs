//! The embedded baking service of this build (the `service` feature): `bspvt-server`'s
//! service in this process, on a loopback port.

use bspvt_client::stream::source::Embedded;

/// This build's embedded service, if it has one.
#[cfg(feature = "service")]
pub(crate) const EMBEDDED: Option<&'static dyn Embedded> = Some(&InProcess);
/// This build's embedded service, if it has one.
#[cfg(not(feature = "service"))]
pub(crate) const EMBEDDED: Option<&'static dyn Embedded> = None;

/// `bspvt_server::service::Background` on 127.0.0.1, a free port.
#[cfg(feature = "service")]
struct InProcess;

#[cfg(feature = "service")]
impl Embedded for InProcess {
    fn start(
        &self,
        data_dir: &std::path::Path,
    ) -> anyhow::Result<bspvt_client::stream::source::EmbeddedService> {
        use bspvt_server::service::{Background, Config};
        let mut cfg = Config::with_data_dir(data_dir);
        cfg.addr = std::net::SocketAddr::from(([127, 0, 0, 1], 0));
        let bg = Background::start(cfg)?;
        Ok(bspvt_client::stream::source::EmbeddedService {
            addr: bg.addr,
            guard: Box::new(bg),
        })
    }
}
