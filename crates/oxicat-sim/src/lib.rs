//! `oxicat-sim`: the virtual EtherCAT segment.
