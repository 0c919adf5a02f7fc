// slave 0: EtherCAT_Application_SPI (PDO mapping from CoE)

/// RxPDO, SM2: written by the master.
#[derive(Debug, Clone, Copy, PartialEq, Default, ethercrab_wire::EtherCrabWireReadWrite)]
#[wire(bytes = 24)]
pub struct Slave0Outputs {
    /// 0x7000:01 Button1 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button1: bool,
    /// 0x7000:02 Button2 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button2: bool,
    /// 0x7000:03 Button3 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button3: bool,
    /// 0x7000:04 Button4 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button4: bool,
    /// 0x7000:05 Blue_LED (PDO 0x1600)
    #[wire(bits = 1)]
    pub blue_led: bool,
    /// 0x7000:06 Red_LED (PDO 0x1600)
    #[wire(bits = 1)]
    pub red_led: bool,
    /// 0x7000:07 Button7 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button7: bool,
    /// 0x7000:08 Button8 (PDO 0x1600)
    #[wire(bits = 1)]
    pub button8: bool,
    /// 0x7000:09 Sync (PDO 0x1600)
    #[wire(bits = 8)]
    pub sync: i8,
    /// 0x7010:01 OutINT32Var1 (PDO 0x1601)
    #[wire(bits = 32)]
    pub out_int32_var1: i32,
    /// 0x7012:01 OutUINT16Var1 (PDO 0x1601)
    #[wire(bits = 16)]
    pub out_uint16_var1: u16,
    /// 0x7014:01 OutINT32Var2 (PDO 0x1601)
    #[wire(bits = 32)]
    pub out_int32_var2: i32,
    /// 0x7020:01 OutINT16Var1 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var1: i16,
    /// 0x7020:02 OutINT16Var2 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var2: i16,
    /// 0x7020:03 OutINT16Var3 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var3: i16,
    /// 0x7020:04 OutINT16Var4 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var4: i16,
    /// 0x7020:05 OutINT16Var5 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var5: i16,
    /// 0x7020:06 OutINT16Var6 (PDO 0x1602)
    #[wire(bits = 16)]
    pub out_int16_var6: i16,
}

/// TxPDO, SM3: read by the master.
#[derive(Debug, Clone, Copy, PartialEq, Default, ethercrab_wire::EtherCrabWireReadWrite)]
#[wire(bytes = 22)]
pub struct Slave0Inputs {
    /// 0x6010:01 InINT32Var1 (PDO 0x1A01)
    #[wire(bits = 32)]
    pub in_int32_var1: i32,
    /// 0x6012:01 InUINT16Var1 (PDO 0x1A01)
    #[wire(bits = 16)]
    pub in_uint16_var1: u16,
    /// 0x6014:01 InINT32Var2 (PDO 0x1A01)
    #[wire(bits = 32)]
    pub in_int32_var2: i32,
    /// 0x6020:01 InINT16Var1 (PDO 0x1A02)
    #[wire(bits = 16)]
    pub in_int16_var1: i16,
    /// 0x6020:02 InINT16Var2 (PDO 0x1A02)
    #[wire(bits = 16)]
    pub in_int16_var2: i16,
    /// 0x6030:01 InINT32Var3 (PDO 0x1A03)
    #[wire(bits = 32)]
    pub in_int32_var3: i32,
    /// 0x6030:02 InINT32Var4 (PDO 0x1A03)
    #[wire(bits = 32)]
    pub in_int32_var4: i32,
}

