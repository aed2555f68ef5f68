//! Adam with the reference semantics and the schedule grammar.
