"""The EGL device of the GPU Ray assigned to a job.

Ray gives a GPU task ``CUDA_VISIBLE_DEVICES`` (the ids of the GPUs it reserved: nvidia-smi's
indices, which follow the PCI bus order, or ``GPU-<uuid>`` strings), but crackbake draws through
EGL, whose devices are numbered by the EGL implementation (``eglQueryDevicesEXT``: each vendor's
devices in its own order, software renderers among them) and ignore ``CUDA_VISIBLE_DEVICES``.
The two numberings meet at the PCI address: an EGL device's DRM device file
(``EGL_DRM_DEVICE_FILE_EXT``, ``/dev/dri/cardN``) leads to it through sysfs, and nvidia-smi's
index ``i`` is the ``i``-th NVIDIA GPU in PCI bus order.

Only the mapping is here (a pure function, unit-tested); querying EGL's devices and passing the
index as ``CRACKBAKE_EGL_DEVICE`` needs a GPU machine to test and is not wired in yet.
"""

from __future__ import annotations


def normalise_pci(address: str) -> str:
    """A PCI address as sysfs writes it: ``0000:3b:00.0`` (domain, bus, device, function in
    lower-case hex; nvidia-smi writes ``00000000:3B:00.0``)."""
    parts = address.strip().lower().split(":")
    if len(parts) == 2:  # no domain: bus:device.function
        parts.insert(0, "0")
    if len(parts) != 3 or "." not in parts[2]:
        raise ValueError(f"{address!r} is not a PCI address (domain:bus:device.function)")
    domain, bus, devfn = parts
    device, function = devfn.split(".", 1)
    return f"{int(domain, 16):04x}:{int(bus, 16):02x}:{int(device, 16):02x}.{int(function, 16)}"


def egl_device_for(cuda_visible: str | None, gpu_pci: list[str],
                   egl_pci: list[str | None]) -> int | None:
    """The EGL device index of the first GPU in ``cuda_visible``, or None.

    Parameters
    ----------
    cuda_visible : str or None
        ``CUDA_VISIBLE_DEVICES`` as Ray sets it for the task (``"2"``, ``"2,3"``); only its
        first GPU is used (one context per job).  None, empty, ``-1`` or ``NoDevFiles``: no GPU.
    gpu_pci : list of str
        PCI address of each NVIDIA GPU of the node, in nvidia-smi's index order (PCI bus
        order); any spelling :func:`normalise_pci` reads.
    egl_pci : list of str or None
        PCI address of each EGL device, in EGL's order; None for a device with no PCI address
        (Mesa's software renderer, a surfaceless platform device).

    Returns
    -------
    int or None
        Index into EGL's devices; None when no GPU is visible, the id is a UUID (it names no
        index; the caller then keeps EGL's default device) or no EGL device sits at that GPU's
        PCI address (its driver has no EGL).

    Raises
    ------
    ValueError
        An index outside ``gpu_pci`` (the node's GPUs changed under Ray).
    """
    if cuda_visible is None:
        return None
    first = cuda_visible.split(",")[0].strip()
    if not first or first in ("-1", "NoDevFiles") or not first.lstrip("-").isdigit():
        return None
    index = int(first)
    if not 0 <= index < len(gpu_pci):
        raise ValueError(f"CUDA_VISIBLE_DEVICES names GPU {index} but the node has "
                         f"{len(gpu_pci)} NVIDIA GPUs")
    want = normalise_pci(gpu_pci[index])
    for k, address in enumerate(egl_pci):
        if address is not None and normalise_pci(address) == want:
            return k
    return None
