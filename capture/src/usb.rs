//! USB captures of FTDI-based controllers: usbmon and USBPcap (being written).
