//! The evaluation server: HTTP and gRPC adapters over one service layer, SQLite store, queue, scoring.
