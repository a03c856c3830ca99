//! Message ids as constants, generated from the table at build time (`build.rs`): code that
//! names a message writes `msg::HW_GET_INFO`, and a typo is a compile error instead of a lookup
//! that silently finds nothing. Sub-message ids are in a module per group (`msg::la::…`).

include!(concat!(env!("OUT_DIR"), "/msg_ids.rs"));
