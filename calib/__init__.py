"""Camera profiles shipped with qrfield (installed as the data package ``qrfield_calib``)."""
