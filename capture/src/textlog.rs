//! Logs of serial tools: socat, jpnevulator, interceptty (being written).
