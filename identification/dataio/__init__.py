"""Records in and results out: file readers, the time base, record preparation, HDF5 archives and their storage codecs."""
