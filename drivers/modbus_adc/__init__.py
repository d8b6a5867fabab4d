"""Modbus analog-input modules (+-10 V ADCs over Modbus TCP or RTU): currents, inclinometers."""

from drivers.modbus_adc.channels import ADC_COLUMNS, Channel, ChannelMap
from drivers.modbus_adc.driver import ModbusAdcConfig, ModbusAdcDriver

__all__ = ["ADC_COLUMNS", "Channel", "ChannelMap", "ModbusAdcConfig", "ModbusAdcDriver"]
