//! ROS 2 recordings: the CDR encoding of messages ([`cdr`]), the message types read and written
//! ([`msgs`]), and bags in MCAP ([`bag`]).

pub mod bag;
pub mod cdr;
pub mod msgs;
