"""The skin-tone dataset: sampling, per-tone simulation, chunked HDF5 storage, shards and merge."""
