// cia402-joint (CiA402 joint drive), default PDO assignment

/// RxPDO, SM2: written by the master.
#[derive(Debug, Clone, Copy, PartialEq, Default, ethercrab_wire::EtherCrabWireReadWrite)]
#[wire(bytes = 13)]
pub struct Cia402JointOutputs {
    /// 0x6040:00 Controlword (PDO 0x1600)
    #[wire(bits = 16)]
    pub controlword: u16,
    /// 0x6060:00 Modes of operation (PDO 0x1600)
    #[wire(bits = 8)]
    pub modes_of_operation: i8,
    /// 0x607A:00 Target position (PDO 0x1600)
    #[wire(bits = 32)]
    pub target_position: i32,
    /// 0x60FF:00 Target velocity (PDO 0x1600)
    #[wire(bits = 32)]
    pub target_velocity: i32,
    /// 0x6071:00 Target torque (PDO 0x1600)
    #[wire(bits = 16)]
    pub target_torque: i16,
}

/// TxPDO, SM3: read by the master.
#[derive(Debug, Clone, Copy, PartialEq, Default, ethercrab_wire::EtherCrabWireReadWrite)]
#[wire(bytes = 15)]
pub struct Cia402JointInputs {
    /// 0x6041:00 Statusword (PDO 0x1A00)
    #[wire(bits = 16)]
    pub statusword: u16,
    /// 0x6061:00 Modes of operation display (PDO 0x1A00)
    #[wire(bits = 8)]
    pub modes_of_operation_display: i8,
    /// 0x6064:00 Position actual value (PDO 0x1A00)
    #[wire(bits = 32)]
    pub position_actual_value: i32,
    /// 0x606C:00 Velocity actual value (PDO 0x1A00)
    #[wire(bits = 32)]
    pub velocity_actual_value: i32,
    /// 0x6077:00 Torque actual value (PDO 0x1A00)
    #[wire(bits = 16)]
    pub torque_actual_value: i16,
    /// 0x603F:00 Error code (PDO 0x1A00)
    #[wire(bits = 16)]
    pub error_code: u16,
}
