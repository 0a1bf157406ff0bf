"""The peak resident memory of a child interpreter, measured so that the parent's peak does not leak in.

``resource.getrusage(RUSAGE_SELF).ru_maxrss`` keeps, across ``exec``, the high-water mark of the process
it replaced: a child started by ``subprocess`` from a pytest worker that once held 17 GB reports 17 GB
whatever it does (Linux saves the old memory map's peak into the process's signal struct at exec). The
kernel's ``VmHWM`` belongs to the child's own memory map, so it starts from the child's first page.
"""

# Source text put at the top of the ``python -c`` scripts: defines ``peak_kib()``.
PEAK_KIB_SOURCE = """
def peak_kib():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
"""
