//! pcapng capture files: writer (both directions, ns timestamps) and reader.
