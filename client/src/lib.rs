//! # bspvt client
