' =============================================================================================
' StationLink.prg - the calibration station's robot program for an Epson SCARA (RC700 / RC90
' family, Epson RC+ 7 / 8, SPEL+), register map version 2 (drivers/controller_map.py,
' docs/protocols.md, docs/robot-program.md).
'
' WHAT IT IMPLEMENTS
'   * TRANSPORT: the program is itself the Modbus TCP server. Task ModbusServer opens TCP/IP
'     port #NET_PORT of the controller's Ethernet (Standard Ethernet, no option) as a server and
'     speaks Modbus TCP in binary (ReadBin / WriteBin): function codes 3 and 4 (read), 6 and 16
'     (write), exception 1 for any other function, exception 2 for an address outside the window
'     BASE .. BASE+127 and for a PC write to a register the program writes, exception 3 for a bad
'     count. The window image is Regs(0..127). Chosen because every RC700/RC90 has SPEL+ TCP/IP
'     sockets, while the fieldbus / Modbus slave options differ per controller.
'   * Identification, heartbeat task (0.1 s, hb_robot, watchdog on hb_pc, act_joints), the command
'     handshake with the sequence rule, MOVE_JOINTS, MOVE_CARTESIAN (the controller's inverse
'     kinematics, then the active correction table added by the interpolation rule of
'     docs/protocols.md exactly as drivers/correction_table.py CorrectionTableData.interpolate),
'     STOP, RESET, soft limits checked on what WILL be commanded, e-stop / drive fault / watchdog
'     latching until RESET.
'   * The transfer block (served inside the Modbus request that starts it, as the simulator
'     does): WRITE_HEADER / WRITE_PAGE with the page CRC-32 checked (table-driven CRC-32, the
'     zlib polynomial 0xEDB88320, kept in two 16-bit halves so that no value needs an unsigned
'     32-bit type), READ_HEADER / READ_PAGE of the stored pages, READ_INFO (soft limits, actual
'     pose), READ_{STAGED,ACTIVE,PREVIOUS}_{HEADER,PAGE} of the table in a slot.
'   * Three tables (staged, active, previous) and the commands TABLE_STAGE, TABLE_ACTIVATE,
'     TABLE_DEACTIVATE, TABLE_ROLLBACK, TABLE_DISCARD_PREVIOUS with the slot rules of
'     simulators/controller_tables.py (TableSlots.switch): ACTIVATE over no active table keeps
'     the previous one.
'
' INSTALL AND CONFIGURE
'   1. Add this file to an Epson RC+ project (Project > Edit > add StationLink.prg), build, and
'      set Function main as the program the controller starts (Auto mode or the Run window).
'   2. RC+ Setup > System Configuration > Controller > TCP/IP: port #201 (NET_PORT) as Server,
'      local port 502 (or the port of [devices] controller), binary data, no terminator.
'   3. Set the configuration #defines below: BASE (= [devices] controller_register_base, 0 by
'      default), WORD_ORDER_BIG (1 = "big", 0 = "little", = [devices] word_order), WATCHDOG_MS,
'      TOOL_NO (a Tool defined with TLSet as the station's probe head K), CORRECTION_STATE, and
'      the soft limits in InitConfig (station units: rad, rad, mm, rad; inside the Range).
'   4. The station's robot file must describe this robot as Epson does: joints J1, J2, J4 in
'      Epson's zero and sign (deg in SPEL+, rad on the wire), J3 in mm, base frame = Epson's robot
'      coordinates, nominal arm lengths from the manipulator manual, the elbow flag +1 = J2 > 0;
'      the table then corrects what the controller's own kinematics miss.
'   5. With the robot parked at [conformance].park_joints run `station conformance CONFIG` before
'      the first calibration.
'
' WHAT WAS CHECKED
'   * The logic was traced by hand against the simulated program (simulators/controller_server.py,
'     simulators/controller_tables.py, drivers/correction_table.py): the order of the checks, the
'     error codes, the slot rules, the interpolation (periodic axes, single-node axes, the 1e-6
'     node tolerance and the clamp), results written before the sequence number that announces
'     them.
'   * tests/test_robot_programs.py checks that every register offset, header offset, command
'     code, error code, transfer operation, status bit and the map version #defined below equal
'     drivers/controller_map.py, and that every entry of the map is declared here.
'   * The JA function (joint angles -> point) was checked against Epson's SPEL+ Language
'     Reference (download.epson.biz, SPEL, "JA Function"). Every other statement - Function /
'     Fend, Xqt ... NoEmgAbort, Do / Loop, Select / Send, Wait, Go ... Till, TillOn, MemOn /
'     MemOff / MemSw, Agl, PAgl, XY(...) /L /R, CX / CY / CZ / CU, Here, Tool, Speed, Accel,
'     EStopOn, OnErr / Err / ErrAxis / EResume, TmReset / Tmr, OpenNet / WaitNet / ChkNet /
'     ReadBin / WriteBin / CloseNet, LShift / RShift, Int32 / Long / Double arrays - is written
'     from the SPEL+ Language Reference as remembered: CONFIRM each in the reference of your RC+
'     version, in particular ReadBin / WriteBin on a TCP/IP port, the Byte type's range, the size
'     allowed for Global arrays (the table store needs about 160 000 Long elements) and that a
'     NoEmgAbort task keeps running during an emergency stop on your controller.
'
' WHAT WAS NOT DONE
'   * This program has NOT run on a real controller, nor in the RC+ simulator. It was not
'     compiled. Build it in RC+ first and fix what the compiler says.
'   * One Modbus client at a time (the station); a second connection waits.
'   * The controller's own kinematics and any arm calibration set with ArmSet are the "nominal"
'     inverse kinematics here: CORRECTION_STATE defaults to 2 (unknown); set 0 once you have
'     checked that no arm calibration is set.
' =============================================================================================

' ---------------- configuration (the integrator sets these) ---------------------------------
#define BASE 0
#define WORD_ORDER_BIG 1
#define WATCHDOG_MS 1000
#define N_JOINTS 4
#define NET_PORT 201
#define TOOL_NO 1
#define CORRECTION_STATE 2
#define STOP_BIT 0

' ---------------- register map 2 (tests/test_robot_programs.py keeps these true) -------------
#define MAP_VERSION 2
#define WINDOW_SIZE 128
#define PAGE_DATA_REGISTERS 58
#define PAGE_VALUES 29
#define MAX_TABLE_VALUES 32000
#define MAX_PAGES 1104
#define TABLE_FORMAT_VERSION 2
#define TABLE_HEADER_REGISTERS 30
#define ORDER_CHECK_VALUE 1
#define R_HB_PC 0
#define R_HB_ROBOT 1
#define R_MAP_VERSION 2
#define R_N_JOINTS 3
#define R_WATCHDOG_MS 4
#define R_CORRECTION_STATE 5
#define R_ORDER_CHECK 6
#define R_CMD_CODE 8
#define R_CMD_SEQ 9
#define R_CMD_ELBOW 10
#define R_CMD_SPEED 11
#define R_CMD_JOINTS 12
#define R_CMD_POSE 24
#define R_ACK_SEQ 36
#define R_DONE_SEQ 37
#define R_ERROR_SEQ 38
#define R_ERROR_CODE 39
#define R_STATUS 40
#define R_ERROR_JOINT 41
#define R_ERROR_BOUND 42
#define R_XFER_ACK 43
#define R_XFER_ERROR 44
#define R_ACT_JOINTS 45
#define R_TABLE_STAGED_CRC 57
#define R_TABLE_ACTIVE_CRC 59
#define R_TABLE_PREVIOUS_CRC 61
#define R_XFER_SEQ 63
#define R_XFER_OP 64
#define R_PAGE_INDEX 65
#define R_PAGE_LEN 66
#define R_PAGE_CRC 67
#define R_PAGE_DATA 69
#define H_TABLE_FORMAT 0
#define H_TABLE_N_AXES 1
#define H_TABLE_SHAPE 2
#define H_TABLE_START 6
#define H_TABLE_STEP 14
#define H_TABLE_PERIODIC 22
#define H_TABLE_N_JOINTS 23
#define H_TABLE_N_CONFIGS 24
#define H_TABLE_N_VALUES 25
#define H_TABLE_CRC 27
#define H_TABLE_VALUE_SCALE_EXP 29
#define INFO_SOFT_LIMITS 0
#define INFO_ACT_POSE 1
#define C_NONE 0
#define C_MOVE_JOINTS 1
#define C_MOVE_CARTESIAN 2
#define C_STOP 3
#define C_RESET 4
#define C_TABLE_STAGE 10
#define C_TABLE_ACTIVATE 11
#define C_TABLE_DEACTIVATE 12
#define C_TABLE_ROLLBACK 13
#define C_TABLE_DISCARD_PREVIOUS 14
#define X_NONE 0
#define X_WRITE_HEADER 1
#define X_WRITE_PAGE 2
#define X_READ_HEADER 3
#define X_READ_PAGE 4
#define X_READ_INFO 5
#define X_READ_STAGED_HEADER 6
#define X_READ_STAGED_PAGE 7
#define X_READ_ACTIVE_HEADER 8
#define X_READ_ACTIVE_PAGE 9
#define X_READ_PREVIOUS_HEADER 10
#define X_READ_PREVIOUS_PAGE 11
#define CS_NONE 0
#define CS_VENDOR 1
#define CS_UNKNOWN 2
#define E_NONE 0
#define E_SOFT_LIMIT 1
#define E_UNREACHABLE 2
#define E_ESTOP 3
#define E_DRIVE_FAULT 4
#define E_BAD_COMMAND 5
#define E_SEQUENCE_ERROR 6
#define E_TABLE_CRC_MISMATCH 7
#define E_TABLE_NOT_STAGED 8
#define E_TABLE_SHAPE_INVALID 9
#define E_TARGET_OUTSIDE_TABLE 10
#define E_WATCHDOG_TIMEOUT 11
#define E_NOT_READY 12
#define E_MOTION_ABORTED 13
#define E_NO_PREVIOUS_TABLE 14
#define E_PAGE_CRC_MISMATCH 15
#define E_PAGE_INVALID 16
#define S_READY 1
#define S_MOVING 2
#define S_IN_POSITION 4
#define S_ERROR 8
#define S_ESTOP 16
#define S_TABLE_ACTIVE 32
#define S_TABLE_STAGED 64
#define S_TABLE_PREVIOUS 128
' slots: index into SlotBuf
#define SLOT_STAGED 0
#define SLOT_ACTIVE 1
#define SLOT_PREVIOUS 2

' ---------------- global state ----------------------------------------------------------
' the window image (offsets 0..127), and which offsets the PC may not write
Global Long Regs(127)
Global Boolean ReadOnly(127)
' the command block as it arrived (offsets 8..35), and that a write covered cmd_seq
Global Long CmdSnap(27)
Global Boolean CmdWritten
' the transfer store: header page and value pages as the PC wrote them (0 = no such page)
Global Long StoreHdr(29)
Global Integer StoreHdrLen
Global Long StoreReg(1103, 57)
Global Integer StoreLen(1103)
' three table buffers: raw i32 values, canonical header page; SlotBuf(slot) = buffer or -1
Global Long TBuf(2, 31999)
Global Long THdr(2, 29)
Global Integer SlotBuf(2)
' CRC-32 table in two 16-bit halves, and the running CRC
Global Long CrcTabHi(255), CrcTabLo(255)
Global Long CrcHi, CrcLo
' robot state
Global Double SoftLo(3), SoftHi(3)
Global Long Status
Global Boolean Latched, Moving, InPosition, WdFired
Global Long LastSeq, MotionSeq, HbRobot, LastXfer
Global Double Tq(3)
Global Integer MoveSpeedPct
' 0 running, 1 arrived, 2 stopped by STOP (Till), 3 error
Global Integer MoveResult
Global Integer MoveErrAxis
' Modbus frame buffers (bytes as 0..255 in Long; ReadBin / WriteBin use the Byte arrays)
Global Byte RxB(299), TxB(299)
Global Long Rx(299), Tx(299)

' ---------------- start ---------------------------------------------------------------
Function main
    Integer i
    InitConfig
    CrcInit
    For i = 0 To 127
        Regs(i) = 0
        ReadOnly(i) = False
    Next
    ' what the program writes: hb_robot .. order_check and ack_seq .. table_previous_crc
    For i = R_HB_ROBOT To R_ORDER_CHECK + 1
        ReadOnly(i) = True
    Next
    For i = R_ACK_SEQ To R_TABLE_PREVIOUS_CRC + 1
        ReadOnly(i) = True
    Next
    For i = 0 To 2
        SlotBuf(i) = -1
    Next
    StoreHdrLen = 0
    For i = 0 To MAX_PAGES - 1
        StoreLen(i) = 0
    Next
    Regs(R_MAP_VERSION) = MAP_VERSION
    Regs(R_N_JOINTS) = N_JOINTS
    Regs(R_WATCHDOG_MS) = WATCHDOG_MS
    Regs(R_CORRECTION_STATE) = CORRECTION_STATE
    PutI32 R_ORDER_CHECK, ORDER_CHECK_VALUE
    Latched = False
    Moving = False
    InPosition = True
    LastSeq = 0
    LastXfer = 0
    HbRobot = 0
    Tool TOOL_NO
    WriteActJoints
    PublishStatus
    Xqt ModbusServer, NoEmgAbort
    Xqt Heartbeat, NoEmgAbort
    Xqt CommandLoop, NoEmgAbort
Fend

' soft limits in station units (rad, rad, mm, rad): set them for your robot
Function InitConfig
    SoftLo(0) = DegToRad(-130): SoftHi(0) = DegToRad(130)
    SoftLo(1) = DegToRad(-145): SoftHi(1) = DegToRad(145)
    SoftLo(2) = -200: SoftHi(2) = 0
    SoftLo(3) = DegToRad(-360): SoftHi(3) = DegToRad(360)
Fend

' ---------------- words and scaled integers --------------------------------------------
Function U32Hi(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Hi = Regs(off)
    Else
        U32Hi = Regs(off + 1)
    EndIf
Fend

Function U32Lo(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        U32Lo = Regs(off + 1)
    Else
        U32Lo = Regs(off)
    EndIf
Fend

' signed 32-bit value from its words; (hi - 65536) * 65536 + lo stays in range when negative
Function JoinI32(hi As Long, lo As Long) As Long
    If hi >= 32768 Then
        JoinI32 = (hi - 65536) * 65536 + lo
    Else
        JoinI32 = hi * 65536 + lo
    EndIf
Fend

Function GetI32(off As Integer) As Long
    GetI32 = JoinI32(U32Hi(off), U32Lo(off))
Fend

Function GetI16(off As Integer) As Long
    If Regs(off) >= 32768 Then
        GetI16 = Regs(off) - 65536
    Else
        GetI16 = Regs(off)
    EndIf
Fend

Function HiWord(v As Long) As Long
    HiWord = RShift(v, 16) And &HFFFF
Fend

Function LoWord(v As Long) As Long
    LoWord = v And &HFFFF
Fend

Function PutWords(off As Integer, hi As Long, lo As Long)
    If WORD_ORDER_BIG = 1 Then
        Regs(off) = hi: Regs(off + 1) = lo
    Else
        Regs(off) = lo: Regs(off + 1) = hi
    EndIf
Fend

Function PutI32(off As Integer, v As Long)
    PutWords off, HiWord(v), LoWord(v)
Fend

Function PutI16(off As Integer, v As Long)
    If v < 0 Then
        Regs(off) = v + 65536
    Else
        Regs(off) = v
    EndIf
Fend

' floor for a Double, whatever Int does with negative numbers
Function FloorD(x As Double) As Double
    Double f
    f = Int(x)
    If f > x Then f = f - 1
    FloorD = f
Fend

' value -> scaled count, rounded
Function Counts(x As Double, perUnit As Double) As Long
    Counts = FloorD(x * perUnit + 0.5)
Fend

' ---------------- CRC-32 (zlib / ISO-HDLC), table-driven in 16-bit halves ----------------
Function CrcInit
    Integer n, k
    Long hi, lo, c
    For n = 0 To 255
        hi = 0: lo = n
        For k = 1 To 8
            c = lo And 1
            lo = RShift(lo, 1) Or LShift(hi And 1, 15)
            hi = RShift(hi, 1)
            If c = 1 Then
                hi = hi Xor &HEDB8
                lo = lo Xor &H8320
            EndIf
        Next
        CrcTabHi(n) = hi: CrcTabLo(n) = lo
    Next
Fend

Function CrcStart
    CrcHi = &HFFFF: CrcLo = &HFFFF
Fend

Function CrcByte(b As Long)
    Integer idx
    idx = (CrcLo And &HFF) Xor b
    CrcLo = (RShift(CrcLo, 8) Or LShift(CrcHi And &HFF, 8)) Xor CrcTabLo(idx)
    CrcHi = RShift(CrcHi, 8) Xor CrcTabHi(idx)
Fend

' one register, high byte first
Function CrcWord(w As Long)
    CrcByte RShift(w, 8) And &HFF
    CrcByte w And &HFF
Fend

Function CrcEnd
    CrcHi = CrcHi Xor &HFFFF: CrcLo = CrcLo Xor &HFFFF
Fend

' ---------------- status and results ---------------------------------------------------
Function PublishStatus
    Long s
    s = 0
    If Not Latched Then s = s + S_READY
    If Moving Then s = s + S_MOVING
    If InPosition Then s = s + S_IN_POSITION
    If Latched Then s = s + S_ERROR
    If (Status And S_ESTOP) <> 0 And Latched Then s = s + S_ESTOP
    If SlotBuf(SLOT_ACTIVE) >= 0 Then s = s + S_TABLE_ACTIVE
    If SlotBuf(SLOT_STAGED) >= 0 Then s = s + S_TABLE_STAGED
    If SlotBuf(SLOT_PREVIOUS) >= 0 Then s = s + S_TABLE_PREVIOUS
    Status = s
    Regs(R_STATUS) = s
    PublishCrc SLOT_STAGED, R_TABLE_STAGED_CRC
    PublishCrc SLOT_ACTIVE, R_TABLE_ACTIVE_CRC
    PublishCrc SLOT_PREVIOUS, R_TABLE_PREVIOUS_CRC
Fend

' the slot's whole-table CRC (its header's, checked at TABLE_STAGE), 0 for an empty slot
Function PublishCrc(slot As Integer, off As Integer)
    Integer b
    b = SlotBuf(slot)
    If b < 0 Then
        PutWords off, 0, 0
    ElseIf WORD_ORDER_BIG = 1 Then
        PutWords off, THdr(b, H_TABLE_CRC), THdr(b, H_TABLE_CRC + 1)
    Else
        PutWords off, THdr(b, H_TABLE_CRC + 1), THdr(b, H_TABLE_CRC)
    EndIf
Fend

' details first, the sequence number last; latching codes latch
Function Refuse(seq As Long, code As Integer, joint As Integer, bound As Integer)
    Regs(R_ERROR_CODE) = code
    PutI16 R_ERROR_JOINT, joint
    PutI16 R_ERROR_BOUND, bound
    If code = E_ESTOP Or code = E_DRIVE_FAULT Or code = E_WATCHDOG_TIMEOUT Then
        Latched = True
        If code = E_ESTOP Then Status = Status Or S_ESTOP
        PublishStatus
    EndIf
    Regs(R_ERROR_SEQ) = seq
Fend

Function Done(seq As Long)
    Regs(R_DONE_SEQ) = seq
Fend

Function WriteActJoints
    Integer j
    Double v
    For j = 0 To 5
        v = 0
        If j < N_JOINTS Then
            v = Agl(j + 1)
            ' J3 is prismatic (mm); the others deg -> rad
            If j <> 2 Then v = DegToRad(v)
        EndIf
        PutI32 R_ACT_JOINTS + 2 * j, Counts(v, 1000000)
    Next
Fend

' ---------------- heartbeat: every 0.1 s, also while moving -----------------------------
Function Heartbeat
    Long hbPcLast
    hbPcLast = Regs(R_HB_PC)
    TmReset 0
    Do
        HbRobot = (HbRobot + 1) Mod 65536
        Regs(R_HB_ROBOT) = HbRobot
        If Regs(R_HB_PC) <> hbPcLast Then
            hbPcLast = Regs(R_HB_PC)
            TmReset 0
        EndIf
        If Moving And Tmr(0) * 1000 > WATCHDOG_MS Then WdFired = True
        WriteActJoints
        Wait 0.1
    Loop
Fend

' ---------------- the motion task (one per move) -------------------------------------------
Function MoveTask
    OnErr GoTo MoveErr
    Speed MoveSpeedPct
    Accel MoveSpeedPct, MoveSpeedPct
    Go JA(RadToDeg(Tq(0)), RadToDeg(Tq(1)), Tq(2), RadToDeg(Tq(3))) Till MemSw(STOP_BIT) = On
    If TillOn Then
        MoveResult = 2
    Else
        MoveResult = 1
    EndIf
    Exit Function
MoveErr:
    MoveErrAxis = ErrAxis
    MoveResult = 3
    EResume Next
Fend

' stop the running motion and wait until the motion task has ended
Function StopMotion
    MemOn STOP_BIT
    Do While MoveResult = 0 And Not EStopOn
        Wait 0.01
    Loop
    Moving = False
    WriteActJoints
    PublishStatus
Fend

' ---------------- the command loop ---------------------------------------------------------
Function CommandLoop
    Long seq, expected, code
    LastSeq = Regs(R_CMD_SEQ)
    Do
        If Moving And EStopOn And Not Latched Then
            Moving = False
            WriteActJoints
            Refuse MotionSeq, E_ESTOP, 0, 0
        ElseIf Moving And WdFired Then
            StopMotion
            Refuse MotionSeq, E_WATCHDOG_TIMEOUT, 0, 0
        ElseIf Moving And MoveResult = 1 Then
            Moving = False
            InPosition = True
            WriteActJoints
            PublishStatus
            Done MotionSeq
        ElseIf Moving And MoveResult = 3 Then
            Moving = False
            WriteActJoints
            Refuse MotionSeq, E_DRIVE_FAULT, MoveErrAxis, 0
        EndIf
        If CmdWritten And CmdSnap(R_CMD_SEQ - R_CMD_CODE) <> LastSeq Then
            CmdWritten = False
            seq = CmdSnap(R_CMD_SEQ - R_CMD_CODE)
            expected = LastSeq Mod 65535 + 1
            LastSeq = seq
            code = CmdSnap(0)
            Regs(R_ACK_SEQ) = seq
            If seq <> expected Then
                Refuse seq, E_SEQUENCE_ERROR, 0, 0
            Else
                Dispatch seq, code
            EndIf
        EndIf
        Wait 0.002
    Loop
Fend

Function SnapI32(off As Integer) As Long
    Integer a
    a = off - R_CMD_CODE
    If WORD_ORDER_BIG = 1 Then
        SnapI32 = JoinI32(CmdSnap(a), CmdSnap(a + 1))
    Else
        SnapI32 = JoinI32(CmdSnap(a + 1), CmdSnap(a))
    EndIf
Fend

Function Dispatch(seq As Long, code As Long)
    Long elbow, speed
    Integer j, err, bound
    Double pose(5), dq(3)
    If code = C_STOP Then
        If Moving Then
            StopMotion
            Refuse MotionSeq, E_MOTION_ABORTED, 0, 0
        EndIf
        Done seq
        Exit Function
    EndIf
    ' only STOP while a motion runs
    If Moving Then
        Refuse seq, E_BAD_COMMAND, 0, 0
        Exit Function
    EndIf
    elbow = CmdSnap(R_CMD_ELBOW - R_CMD_CODE)
    If elbow >= 32768 Then elbow = elbow - 65536
    speed = CmdSnap(R_CMD_SPEED - R_CMD_CODE)
    Select code
        Case C_RESET
            Latched = False
            Status = Status And Not S_ESTOP
            Regs(R_ERROR_CODE) = E_NONE
            PutI16 R_ERROR_JOINT, 0
            PutI16 R_ERROR_BOUND, 0
            PublishStatus
            Done seq
        Case C_MOVE_JOINTS, C_MOVE_CARTESIAN
            If Latched Then
                Refuse seq, E_NOT_READY, 0, 0
                Exit Function
            EndIf
            If speed < 1 Or speed > 1000 Then
                Refuse seq, E_BAD_COMMAND, 0, 0
                Exit Function
            EndIf
            If code = C_MOVE_JOINTS Then
                For j = 0 To N_JOINTS - 1
                    Tq(j) = SnapI32(R_CMD_JOINTS + 2 * j) * 0.000001
                Next
            Else
                If elbow <> 1 And elbow <> -1 Then
                    Refuse seq, E_BAD_COMMAND, 0, 0
                    Exit Function
                EndIf
                For j = 0 To 5
                    pose(j) = SnapI32(R_CMD_POSE + 2 * j) * 0.000001
                Next
                If Not NominalIK(pose(0), pose(1), pose(2), pose(5), elbow) Then
                    Refuse seq, E_UNREACHABLE, 0, 0
                    Exit Function
                EndIf
                If SlotBuf(SLOT_ACTIVE) >= 0 Then
                    err = Interpolate(SlotBuf(SLOT_ACTIVE), pose(0), pose(1), pose(2), pose(5), elbow, dq())
                    If err <> E_NONE Then
                        Refuse seq, err, 0, 0
                        Exit Function
                    EndIf
                    For j = 0 To N_JOINTS - 1
                        Tq(j) = Tq(j) + dq(j)
                    Next
                EndIf
            EndIf
            ' the limit check on what WILL be commanded; a NaN fails it too
            For j = 0 To N_JOINTS - 1
                If Not (SoftLo(j) <= Tq(j) And Tq(j) <= SoftHi(j)) Then
                    bound = 1
                    If Tq(j) < SoftLo(j) Then bound = -1
                    Refuse seq, E_SOFT_LIMIT, j + 1, bound
                    Exit Function
                EndIf
            Next
            MoveSpeedPct = Int(speed / 10 + 0.5)
            If MoveSpeedPct < 1 Then MoveSpeedPct = 1
            MoveResult = 0
            WdFired = False
            MotionSeq = seq
            Moving = True
            InPosition = False
            PublishStatus
            MemOff STOP_BIT
            Xqt MoveTask
        Case C_TABLE_STAGE
            err = StageTable
            PublishStatus
            If err <> E_NONE Then
                Refuse seq, err, 0, 0
            Else
                Done seq
            EndIf
        Case C_TABLE_ACTIVATE, C_TABLE_DEACTIVATE, C_TABLE_ROLLBACK, C_TABLE_DISCARD_PREVIOUS
            err = SwitchTables(code)
            PublishStatus
            If err <> E_NONE Then
                Refuse seq, err, 0, 0
            Else
                Done seq
            EndIf
        Default
            ' also NONE (0) and unknown codes
            Refuse seq, E_BAD_COMMAND, 0, 0
    Send
Fend

' the controller's own inverse kinematics of (x, y, z mm, yaw rad) in the configuration whose J2
' has the sign of elbow; the joints in Tq (station units). False: not reachable.
Function NominalIK(x As Double, y As Double, z As Double, yaw As Double, elbow As Long) As Boolean
    Integer j, tries
    Double j2
    OnErr GoTo IkErr
    NominalIK = False
    For tries = 1 To 2
        If tries = 1 Then
            P900 = XY(x, y, z, RadToDeg(yaw)) /L
        Else
            P900 = XY(x, y, z, RadToDeg(yaw)) /R
        EndIf
        j2 = PAgl(P900, 2)
        If (elbow = 1 And j2 > 0) Or (elbow = -1 And j2 < 0) Then
            For j = 0 To N_JOINTS - 1
                Tq(j) = PAgl(P900, j + 1)
                If j <> 2 Then Tq(j) = DegToRad(Tq(j))
            Next
            NominalIK = True
            Exit Function
        EndIf
    Next
    Exit Function
IkErr:
    NominalIK = False
    EResume Next
Fend

' ---------------- the correction table ------------------------------------------------------
Function HdrU32(b As Integer, off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        HdrU32 = JoinI32(THdr(b, off), THdr(b, off + 1))
    Else
        HdrU32 = JoinI32(THdr(b, off + 1), THdr(b, off))
    EndIf
Fend

Function StoreI32(off As Integer) As Long
    If WORD_ORDER_BIG = 1 Then
        StoreI32 = JoinI32(StoreHdr(off), StoreHdr(off + 1))
    Else
        StoreI32 = JoinI32(StoreHdr(off + 1), StoreHdr(off))
    EndIf
Fend

' TABLE_STAGE: the stored header checked as CorrectionTableData.decode_header and TableAxis do,
' every value page 0 .. ceil(n/29)-1 stored and n values long together, the whole-table CRC-32
' over the values as big-endian bytes; then the table goes into a free buffer as the staged one
Function StageTable As Integer
    Integer nAxes, i, k, b, nPages, used
    Long nValues, nJoints, nConfigs, prodShape, total, crcHi, crcLo, st, sp, hi, lo, v
    StageTable = E_TABLE_SHAPE_INVALID
    If StoreHdrLen <> TABLE_HEADER_REGISTERS Then Exit Function
    If StoreHdr(H_TABLE_FORMAT) <> TABLE_FORMAT_VERSION Then Exit Function
    ' -8 as an i16 word
    If StoreHdr(H_TABLE_VALUE_SCALE_EXP) <> 65528 Then Exit Function
    nAxes = StoreHdr(H_TABLE_N_AXES)
    If nAxes < 1 Or nAxes > 4 Then Exit Function
    prodShape = 1
    For i = 0 To nAxes - 1
        st = StoreI32(H_TABLE_START + 2 * i)
        sp = StoreI32(H_TABLE_STEP + 2 * i)
        If Abs(st) >= 2000000000 Or Abs(sp) >= 2000000000 Or sp <= 0 Then Exit Function
        If StoreHdr(H_TABLE_SHAPE + i) < 1 Then Exit Function
        prodShape = prodShape * StoreHdr(H_TABLE_SHAPE + i)
        If prodShape > MAX_TABLE_VALUES Then Exit Function
    Next
    nJoints = StoreHdr(H_TABLE_N_JOINTS)
    nConfigs = StoreHdr(H_TABLE_N_CONFIGS)
    If nConfigs < 1 Or nConfigs > 2 Or nJoints < 1 Or nJoints > 6 Then Exit Function
    nValues = StoreI32(H_TABLE_N_VALUES)
    If nValues <> nConfigs * prodShape * nJoints Or nValues > MAX_TABLE_VALUES Then Exit Function
    If nJoints <> N_JOINTS Then Exit Function
    nPages = Int((nValues + PAGE_VALUES - 1) / PAGE_VALUES)
    total = 0
    For k = 0 To nPages - 1
        If StoreLen(k) = 0 Then Exit Function
        total = total + StoreLen(k)
    Next
    If total <> 2 * nValues Then Exit Function
    ' first pass: the CRC over the values as big-endian two's-complement bytes
    CrcStart
    For k = 0 To nPages - 1
        For i = 0 To StoreLen(k) - 1 Step 2
            If WORD_ORDER_BIG = 1 Then
                CrcWord StoreReg(k, i): CrcWord StoreReg(k, i + 1)
            Else
                CrcWord StoreReg(k, i + 1): CrcWord StoreReg(k, i)
            EndIf
        Next
    Next
    CrcEnd
    If WORD_ORDER_BIG = 1 Then
        crcHi = StoreHdr(H_TABLE_CRC): crcLo = StoreHdr(H_TABLE_CRC + 1)
    Else
        crcHi = StoreHdr(H_TABLE_CRC + 1): crcLo = StoreHdr(H_TABLE_CRC)
    EndIf
    If CrcHi <> crcHi Or CrcLo <> crcLo Then
        StageTable = E_TABLE_CRC_MISMATCH
        Exit Function
    EndIf
    ' second pass: into the staged slot's buffer, or one no slot uses
    b = SlotBuf(SLOT_STAGED)
    If b < 0 Then
        For b = 0 To 2
            used = 0
            If SlotBuf(SLOT_ACTIVE) = b Or SlotBuf(SLOT_PREVIOUS) = b Then used = 1
            If used = 0 Then Exit For
        Next
    EndIf
    v = 0
    For k = 0 To nPages - 1
        For i = 0 To StoreLen(k) - 1 Step 2
            If WORD_ORDER_BIG = 1 Then
                hi = StoreReg(k, i): lo = StoreReg(k, i + 1)
            Else
                hi = StoreReg(k, i + 1): lo = StoreReg(k, i)
            EndIf
            TBuf(b, v) = JoinI32(hi, lo)
            v = v + 1
        Next
    Next
    ' the header as CorrectionTableData.header_registers writes it: unused axes 0
    For i = 0 To TABLE_HEADER_REGISTERS - 1
        THdr(b, i) = StoreHdr(i)
    Next
    For i = nAxes To 3
        THdr(b, H_TABLE_SHAPE + i) = 0
        THdr(b, H_TABLE_START + 2 * i) = 0: THdr(b, H_TABLE_START + 2 * i + 1) = 0
        THdr(b, H_TABLE_STEP + 2 * i) = 0: THdr(b, H_TABLE_STEP + 2 * i + 1) = 0
    Next
    THdr(b, H_TABLE_PERIODIC) = StoreHdr(H_TABLE_PERIODIC) And (LShift(1, nAxes) - 1)
    SlotBuf(SLOT_STAGED) = b
    StageTable = E_NONE
Fend

' the slot rules of simulators/controller_tables.py TableSlots.switch
Function SwitchTables(code As Long) As Integer
    Integer t
    SwitchTables = E_NONE
    Select code
        Case C_TABLE_ACTIVATE
            If SlotBuf(SLOT_STAGED) < 0 Then
                SwitchTables = E_TABLE_NOT_STAGED
                Exit Function
            EndIf
            ' activating over none keeps the previous table (the one a deactivation set aside)
            If SlotBuf(SLOT_ACTIVE) >= 0 Then SlotBuf(SLOT_PREVIOUS) = SlotBuf(SLOT_ACTIVE)
            SlotBuf(SLOT_ACTIVE) = SlotBuf(SLOT_STAGED)
            SlotBuf(SLOT_STAGED) = -1
        Case C_TABLE_DISCARD_PREVIOUS
            SlotBuf(SLOT_PREVIOUS) = -1
        Case C_TABLE_DEACTIVATE
            If SlotBuf(SLOT_ACTIVE) >= 0 Then
                SlotBuf(SLOT_PREVIOUS) = SlotBuf(SLOT_ACTIVE)
                SlotBuf(SLOT_ACTIVE) = -1
            EndIf
        Case C_TABLE_ROLLBACK
            If SlotBuf(SLOT_PREVIOUS) < 0 Then
                SwitchTables = E_NO_PREVIOUS_TABLE
                Exit Function
            EndIf
            t = SlotBuf(SLOT_ACTIVE)
            SlotBuf(SLOT_ACTIVE) = SlotBuf(SLOT_PREVIOUS)
            SlotBuf(SLOT_PREVIOUS) = t
    Send
Fend

' The interpolation rule of docs/protocols.md (CorrectionTableData.interpolate) on buffer b at
' the target (x, y, z, yaw): dq(0..n_joints-1) in rad or mm. E_TARGET_OUTSIDE_TABLE when a
' non-periodic axis with more than one node does not hold the coordinate (tolerance 1e-6 node).
Function Interpolate(b As Integer, x As Double, y As Double, z As Double, yaw As Double, elbow As Long, ByRef dq() As Double) As Integer
    Integer nAxes, nJoints, nConfigs, cfg, k, j, corner, hiBit, periodic
    Long cnt(3), i0(3), i1(3), idx
    Double u, t(3), w, p(3), start, stp
    p(0) = x: p(1) = y: p(2) = z: p(3) = yaw
    nAxes = THdr(b, H_TABLE_N_AXES)
    nJoints = THdr(b, H_TABLE_N_JOINTS)
    nConfigs = THdr(b, H_TABLE_N_CONFIGS)
    periodic = THdr(b, H_TABLE_PERIODIC)
    cfg = 1
    If elbow = 1 Or nConfigs = 1 Then cfg = 0
    For k = 0 To nAxes - 1
        cnt(k) = THdr(b, H_TABLE_SHAPE + k)
        start = HdrU32(b, H_TABLE_START + 2 * k) * 0.000001
        stp = HdrU32(b, H_TABLE_STEP + 2 * k) * 0.000001
        u = (p(k) - start) / stp
        If (RShift(periodic, k) And 1) = 1 Then
            ' u mod count in [0, count), node count-1 interpolates towards node 0
            u = u - cnt(k) * FloorD(u / cnt(k))
            i0(k) = FloorD(u)
            If i0(k) > cnt(k) - 1 Then i0(k) = cnt(k) - 1
            t(k) = u - i0(k)
            i1(k) = (i0(k) + 1) Mod cnt(k)
        ElseIf cnt(k) = 1 Then
            i0(k) = 0: i1(k) = 0: t(k) = 0
        Else
            If Not (-0.000001 <= u And u <= cnt(k) - 1 + 0.000001) Then
                Interpolate = E_TARGET_OUTSIDE_TABLE
                Exit Function
            EndIf
            If u < 0 Then u = 0
            If u > cnt(k) - 1 Then u = cnt(k) - 1
            i0(k) = FloorD(u)
            If i0(k) > cnt(k) - 2 Then i0(k) = cnt(k) - 2
            t(k) = u - i0(k)
            i1(k) = i0(k) + 1
        EndIf
    Next
    For j = 0 To nJoints - 1
        dq(j) = 0
    Next
    For corner = 0 To LShift(1, nAxes) - 1
        w = 1
        ' flat index in C order: value[cfg][node_0]..[node_{n-1}][joint]
        idx = cfg
        For k = 0 To nAxes - 1
            hiBit = RShift(corner, k) And 1
            If hiBit = 1 Then
                w = w * t(k)
                idx = idx * cnt(k) + i1(k)
            Else
                w = w * (1 - t(k))
                idx = idx * cnt(k) + i0(k)
            EndIf
        Next
        If w <> 0 Then
            For j = 0 To nJoints - 1
                dq(j) = dq(j) + w * (TBuf(b, idx * nJoints + j) * 0.00000001)
            Next
        EndIf
    Next
    Interpolate = E_NONE
Fend

' ---------------- the transfer block (called by ModbusServer inside the request) -------------
Function PageOut(n As Integer)
    Integer i
    CrcStart
    For i = 0 To n - 1
        CrcWord Regs(R_PAGE_DATA + i)
    Next
    CrcEnd
    For i = n To PAGE_DATA_REGISTERS - 1
        Regs(R_PAGE_DATA + i) = 0
    Next
    Regs(R_PAGE_LEN) = n
    PutWords R_PAGE_CRC, CrcHi, CrcLo
Fend

Function ServeTransfer
    Integer op, k, n, i, j, b, slot, nValues, first, count
    Integer err
    Double v
    op = Regs(R_XFER_OP): k = Regs(R_PAGE_INDEX): n = Regs(R_PAGE_LEN)
    err = E_NONE
    If op = X_WRITE_HEADER Or op = X_WRITE_PAGE Then
        If n > PAGE_DATA_REGISTERS Then
            err = E_PAGE_INVALID
        Else
            CrcStart
            For i = 0 To n - 1
                CrcWord Regs(R_PAGE_DATA + i)
            Next
            CrcEnd
            If CrcHi <> U32Hi(R_PAGE_CRC) Or CrcLo <> U32Lo(R_PAGE_CRC) Then
                err = E_PAGE_CRC_MISMATCH
            ElseIf op = X_WRITE_HEADER Then
                If k <> 0 Or n <> TABLE_HEADER_REGISTERS Then
                    err = E_PAGE_INVALID
                Else
                    ' a header page starts a new table: the stored value pages are dropped
                    For i = 0 To n - 1
                        StoreHdr(i) = Regs(R_PAGE_DATA + i)
                    Next
                    StoreHdrLen = n
                    For i = 0 To MAX_PAGES - 1
                        StoreLen(i) = 0
                    Next
                EndIf
            ElseIf k >= MAX_PAGES Or n = 0 Or (n Mod 2) <> 0 Then
                err = E_PAGE_INVALID
            Else
                For i = 0 To n - 1
                    StoreReg(k, i) = Regs(R_PAGE_DATA + i)
                Next
                StoreLen(k) = n
            EndIf
        EndIf
    ElseIf op = X_READ_HEADER Then
        If k <> 0 Or StoreHdrLen = 0 Then
            err = E_PAGE_INVALID
        Else
            For i = 0 To StoreHdrLen - 1
                Regs(R_PAGE_DATA + i) = StoreHdr(i)
            Next
            PageOut StoreHdrLen
        EndIf
    ElseIf op = X_READ_PAGE Then
        If k >= MAX_PAGES Then
            err = E_PAGE_INVALID
        ElseIf StoreLen(k) = 0 Then
            err = E_PAGE_INVALID
        Else
            For i = 0 To StoreLen(k) - 1
                Regs(R_PAGE_DATA + i) = StoreReg(k, i)
            Next
            PageOut StoreLen(k)
        EndIf
    ElseIf op = X_READ_INFO And k = INFO_SOFT_LIMITS Then
        For j = 0 To 5
            If j < N_JOINTS Then
                PutI32 R_PAGE_DATA + 4 * j, Counts(SoftLo(j), 1000000)
                PutI32 R_PAGE_DATA + 4 * j + 2, Counts(SoftHi(j), 1000000)
            Else
                PutI32 R_PAGE_DATA + 4 * j, 0
                PutI32 R_PAGE_DATA + 4 * j + 2, 0
            EndIf
        Next
        PageOut 24
    ElseIf op = X_READ_INFO And k = INFO_ACT_POSE Then
        ' the controller's forward kinematics of the current position, tool TOOL_NO; a SCARA's
        ' roll and pitch are 0
        PutI32 R_PAGE_DATA, Counts(CX(Here), 1000000)
        PutI32 R_PAGE_DATA + 2, Counts(CY(Here), 1000000)
        PutI32 R_PAGE_DATA + 4, Counts(CZ(Here), 1000000)
        PutI32 R_PAGE_DATA + 6, 0
        PutI32 R_PAGE_DATA + 8, 0
        PutI32 R_PAGE_DATA + 10, Counts(DegToRad(CU(Here)), 1000000)
        PageOut 12
    ElseIf op >= X_READ_STAGED_HEADER And op <= X_READ_PREVIOUS_PAGE Then
        ' the table in a slot, regenerated as the PC sent it: staged 6/7, active 8/9, previous 10/11
        slot = Int((op - X_READ_STAGED_HEADER) / 2)
        b = SlotBuf(slot)
        If b < 0 Then
            err = E_PAGE_INVALID
        ElseIf ((op - X_READ_STAGED_HEADER) Mod 2) = 0 Then
            If k <> 0 Then
                err = E_PAGE_INVALID
            Else
                For i = 0 To TABLE_HEADER_REGISTERS - 1
                    Regs(R_PAGE_DATA + i) = THdr(b, i)
                Next
                PageOut TABLE_HEADER_REGISTERS
            EndIf
        Else
            nValues = HdrU32(b, H_TABLE_N_VALUES)
            first = k * PAGE_VALUES
            If first >= nValues Then
                err = E_PAGE_INVALID
            Else
                count = nValues - first
                If count > PAGE_VALUES Then count = PAGE_VALUES
                For i = 0 To count - 1
                    PutI32 R_PAGE_DATA + 2 * i, TBuf(b, first + i)
                Next
                PageOut 2 * count
            EndIf
        EndIf
    Else
        err = E_PAGE_INVALID
    EndIf
    ' the answer, the number last
    Regs(R_XFER_ERROR) = err
    Regs(R_XFER_ACK) = Regs(R_XFER_SEQ)
Fend

' ---------------- Modbus TCP server -----------------------------------------------------
Function RecvBytes(n As Integer) As Boolean
    Integer i
    Long v
    RecvBytes = False
    Do While ChkNet(NET_PORT) < n
        If ChkNet(NET_PORT) < 0 Then Exit Function
        Wait 0.001
    Loop
    ReadBin #NET_PORT, RxB(), n
    For i = 0 To n - 1
        v = RxB(i)
        If v < 0 Then v = v + 256
        Rx(i) = v
    Next
    RecvBytes = True
Fend

Function SendBytes(n As Integer)
    Integer i
    For i = 0 To n - 1
        If Tx(i) > 127 Then
            TxB(i) = Tx(i) - 256
        Else
            TxB(i) = Tx(i)
        EndIf
    Next
    WriteBin #NET_PORT, TxB(), n
Fend

' MBAP header (transaction id, protocol 0, length, unit id) + function code
Function Reply(tid As Long, unit As Long, pduLen As Integer)
    Tx(0) = RShift(tid, 8) And &HFF: Tx(1) = tid And &HFF
    Tx(2) = 0: Tx(3) = 0
    Tx(4) = RShift(pduLen + 1, 8) And &HFF: Tx(5) = (pduLen + 1) And &HFF
    Tx(6) = unit
    SendBytes 7 + pduLen
Fend

Function Exception(tid As Long, unit As Long, fc As Long, code As Integer)
    Tx(7) = fc Or &H80
    Tx(8) = code
    Reply tid, unit, 2
Fend

Function ModbusServer
    Long tid, unit, fc, addr, cnt, lenField, off, val
    Integer i
    Boolean bad
    Do
        OpenNet #NET_PORT As Server
        WaitNet #NET_PORT
        Do
            If Not RecvBytes(7) Then Exit Do
            tid = Rx(0) * 256 + Rx(1)
            lenField = Rx(4) * 256 + Rx(5)
            unit = Rx(6)
            If lenField < 2 Or lenField > 254 Then Exit Do
            If Not RecvBytes(lenField - 1) Then Exit Do
            fc = Rx(0)
            addr = Rx(1) * 256 + Rx(2)
            cnt = Rx(3) * 256 + Rx(4)
            off = addr - BASE
            Select fc
                Case 3, 4
                    If cnt < 1 Or cnt > 125 Then
                        Exception tid, unit, fc, 3
                    ElseIf off < 0 Or off + cnt > WINDOW_SIZE Then
                        Exception tid, unit, fc, 2
                    Else
                        Tx(7) = fc: Tx(8) = 2 * cnt
                        For i = 0 To cnt - 1
                            Tx(9 + 2 * i) = RShift(Regs(off + i), 8) And &HFF
                            Tx(10 + 2 * i) = Regs(off + i) And &HFF
                        Next
                        Reply tid, unit, 2 + 2 * cnt
                    EndIf
                Case 6
                    ' the register's value is in the count field's bytes
                    val = cnt
                    If off < 0 Or off >= WINDOW_SIZE Then
                        Exception tid, unit, fc, 2
                    ElseIf ReadOnly(off) Then
                        Exception tid, unit, fc, 2
                    Else
                        Regs(off) = val
                        AfterWrite off, 1
                        For i = 0 To 4
                            Tx(7 + i) = Rx(i)
                        Next
                        Reply tid, unit, 5
                    EndIf
                Case 16
                    If cnt < 1 Or cnt > 123 Or Rx(5) <> 2 * cnt Then
                        Exception tid, unit, fc, 3
                    ElseIf off < 0 Or off + cnt > WINDOW_SIZE Then
                        Exception tid, unit, fc, 2
                    Else
                        bad = False
                        For i = 0 To cnt - 1
                            If ReadOnly(off + i) Then bad = True
                        Next
                        If bad Then
                            Exception tid, unit, fc, 2
                        Else
                            For i = 0 To cnt - 1
                                Regs(off + i) = Rx(6 + 2 * i) * 256 + Rx(7 + 2 * i)
                            Next
                            AfterWrite off, cnt
                            For i = 0 To 4
                                Tx(7 + i) = Rx(i)
                            Next
                            Reply tid, unit, 5
                        EndIf
                    EndIf
                Default
                    Exception tid, unit, fc, 1
            Send
        Loop
        CloseNet #NET_PORT
    Loop
Fend

' what a PC write starts: the transfer request (xfer_seq changed) at once, and the command block
' handed to CommandLoop when the write covered cmd_seq (the block is written in one request)
Function AfterWrite(off As Integer, cnt As Integer)
    Integer i
    If off <= R_XFER_SEQ And R_XFER_SEQ < off + cnt Then
        If Regs(R_XFER_SEQ) <> LastXfer Then
            LastXfer = Regs(R_XFER_SEQ)
            ServeTransfer
        EndIf
    EndIf
    If off <= R_CMD_SEQ And R_CMD_SEQ < off + cnt Then
        For i = 0 To 27
            CmdSnap(i) = Regs(R_CMD_CODE + i)
        Next
        CmdWritten = True
    EndIf
Fend
