//! Simulation worker: leases episode jobs from the server, runs them on `sim`, calls policies over gRPC.
