"""OpenCL C sources of rtsar, one file per stage; installed as the package ``rtsar.kernels``."""
