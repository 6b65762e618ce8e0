//! zerovar
