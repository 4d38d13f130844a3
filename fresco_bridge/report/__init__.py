"""After-the-run deliverables: the HTML report (``report.html``) and the HDF5 export.

Import the submodules directly (``fresco_bridge.report.html``, ``.hdf5``): matplotlib and h5py
load only when those are used, never in the daemon.
"""
