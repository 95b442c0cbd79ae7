//! Wire contracts (protobuf/gRPC) of Kitchen-R and their conversions to domain types.
