//! One module per subcommand: its options (clap) and the function that runs it.

pub(crate) mod convert;
pub(crate) mod decode;
pub(crate) mod encode;
pub(crate) mod export;
pub(crate) mod info;
pub(crate) mod live;
pub(crate) mod messages;
pub(crate) mod probe;
pub(crate) mod replay;
pub(crate) mod sim;
pub(crate) mod stats;
pub(crate) mod view;
