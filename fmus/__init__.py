"""Everything FMI/SSP: the shared C runtime, C generation from models/, compile + package +
validate, and (later) loading and master algorithms."""
