//! Scripted pick.
