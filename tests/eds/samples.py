"""EDS texts the EDS tests read: a complete EtherNet/IP adapter, and a messy file of the kind
older tools leave behind."""

from __future__ import annotations

#: Identity of the ACG drive's EtherNet/IP card, as the sample [Device] section declares it.
ACG_IDENTITY = {
    "vendor_id": 259,
    "device_type": 2,
    "product_code": 100,
    "revision": (1, 1),
    "product_name": "CENT",
}

ADAPTER_EDS = """\
$ ACG drive with its ACG-ET2 EtherNet/IP card: sample description for the cipstack tests
[File]
    DescText = "ACG-ET2 EtherNet/IP adapter";
    CreateDate = 03-14-2024;
    CreateTime = 09:30:00;
    ModDate = 11-02-2026;
    ModTime = 16:05:42;
    Revision = 1.2;
    HomeURL = "http://www.example.com/acg";

[Device]
    VendCode = 259;
    VendName = "Example Drives";
    ProdType = 2;
    ProdTypeStr = "AC Drive";
    ProdCode = 100;
    MajRev = 1;
    MinRev = 1;
    ProdName = "CENT";
    Catalog = "ACG-ET2";

[Device Classification]
    Class1 = EtherNetIP;

[Params]
    $ the control word has no attribute of its own: no link path
    Param1 =
        0,
        0, "",
        0x0000,
        0xD2, 2,
        "Control Word",
        "",
        "Bit 0 run forward, bit 1 run reverse, bit 2 fault reset",
        0x0000, 0xFFFF, 0x0000,
        , , , ,
        , , , ,
        0;
    Param2 =
        0,
        6, "20 2A 24 01 30 08",
        0x0000,
        0xC3, 2,
        "Speed Reference",
        "rpm",
        "Speed the drive ramps to",
        -3600, 3600, 0,
        1, 1, 1, 0,
        , , , ,
        0;
    Param3 =
        0,
        0, "",
        0x0010,
        0xD2, 2,
        "Status Word",
        "",
        "Bit 0 faulted, bit 2 running forward, bit 7 at reference",
        0x0000, 0xFFFF, 0x0000,
        , , , ,
        , , , ,
        0;
    Param4 =
        0,
        6, "20 2A 24 01 30 07",
        0x0010,
        0xC3, 2,
        "Speed Actual",
        "rpm",
        "Speed the motor turns at",
        -3600, 3600, 0,
        1, 1, 1, 0,
        , , , ,
        0;
    Param5 =
        0,
        6, "20 2A 24 01 30 12",
        0x0004,
        0xC7, 2,
        "Accel Time",
        "s",
        "Time from 0 to high speed",
        1, 32000, 100,
        1, 10, 1, 0,
        , , , ,
        1;
    Param6 =
        0,
        6, "20 2A 24 01 30 13",
        0x0004,
        0xC7, 2,
        "Decel Time",
        "s",
        "Time from high speed to 0",
        1, 32000, 100,
        1, 10, 1, 0,
        , , , ,
        1;
    Param7 =
        0,
        6, "20 29 24 01 30 06",
        0x0012,
        0xC6, 1,
        "Drive State",
        "",
        "Control Supervisor state",
        0, 7, 1,
        , , , ,
        , , , ,
        0;
    Enum7 =
        0, "Vendor Specific",
        1, "Startup",
        2, "Not Ready",
        3, "Ready",
        4, "Enabled",
        5, "Stopping",
        6, "Fault Stop",
        7, "Faulted";
    Param8 =
        0,
        6, "20 2A 24 01 30 06",
        0x0010,
        0xCA, 4,
        "Output Current",
        "A",
        "Motor current",
        0.0, 500.0, 0.0,
        , , , ,
        , , , ,
        1;
    Param9 =
        0,
        0, "",
        0x0000,
        0xC8, 4,
        "RPI Range",
        "microsecond",
        "Requested packet interval",
        2000, 3200000, 10000,
        , , , ,
        , , , ,
        0;

[Groups]
    Group1 = "Control", 4, 1, 2, 3, 4;
    Group2 = "Setup", 3, 5, 6, 9;

[Assembly]
    Assem21 =
        "Extended Speed Control Output",
        "20 04 24 15 30 03",
        4,
        0x0000,
        , ,
        16, Param1,
        16, Param2;
    Assem71 =
        "Extended Speed Control Input",
        "20 04 24 47 30 03",
        4,
        0x0000,
        , ,
        16, Param3,
        16, Param4;
    Assem198 = "Input Only Heartbeat", "20 04 24 C6 30 03", 0, 0x0000, , ;
    Assem199 = "Listen Only Heartbeat", "20 04 24 C7 30 03", 0, 0x0000, , ;

[Connection Manager]
    Connection1 =
        0x04010002,
        0x44640405,
        Param9, 4, Assem21,
        Param9, 4, Assem71,
        , ,
        , ,
        "Exclusive Owner",
        "",
        "20 04 24 01 2C 15 2C 47";
    Connection2 =
        0x02010002,
        0x44640305,
        Param9, 0, Assem198,
        Param9, 4, Assem71,
        , ,
        , ,
        "Input Only",
        "",
        "20 04 24 01 2C C6 2C 47";
    Connection3 =
        0x01010002,
        0x44240305,
        Param9, 0, Assem199,
        Param9, 4, Assem71,
        , ,
        , ,
        "Listen Only",
        "",
        "20 04 24 01 2C C7 2C 47";

[Port]
    Port1 = TCP, "EtherNet/IP Port", "20 F5 24 01", 2;

[Capacity]
    MaxIOConnections = 3;
    MaxMsgConnections = 6;
    TSpec1 = TxRx, 4, 1000;

[TCP/IP Interface Class]
    Revision = 4;
    MaxInst = 1;

[259_Drive Service]
    $ a vendor-specific section: its keywords are the vendor's own
    BootLoader = "2.3";
    Flags = 0x0003, 7;
"""

#: A file as old tools write it: CRLF, Latin-1 text, comments between fields, an entry over
#: several lines with comments inside, strings split into adjacent pieces, hex in any case.
MESSY_EDS: bytes = (
    "$ Fichier EDS \xe9crit \xe0 la main\r\n"
    "$ second header line\r\n"
    "[File]   $ section comment\r\n"
    "DescText=\"Variateur ACG \" \"pour r\xe9seau\";\r\n"
    "CreateDate = 01-02-2020 ; CreateTime=08:00:00;\r\n"
    "Revision = 2.10;\r\n"
    "\r\n"
    "\t[Device]\r\n"
    "  VendCode   =   259 ;  $ vendor\r\n"
    "  VendName = \"Soci\xe9t\xe9 \"\r\n"
    "             \"Exemple\";\r\n"
    "  ProdType = 0X02; ProdTypeStr = \"AC Drive\";\r\n"
    "  ProdCode = 100; MajRev = 1; MinRev = 1;\r\n"
    "  ProdName = \"CENT\"; Catalog = \"ACG-ET2\";\r\n"
    "[Device Classification] Class1 = EtherNetIP;\r\n"
    "[Params]\r\n"
    "$ the only parameter\r\n"
    "Param1 = 0,             $ reserved\r\n"
    "   6, \"20 2a 24 01 30 08\", $ link path\r\n"
    "   $ own-line comment inside the entry\r\n"
    "   0x0000, 0xC3, 2,\r\n"
    "   \"Speed \"  $ comment between two pieces\r\n"
    "   \"Reference\", \"rpm\", \"\",\r\n"
    "   -3600, 3600, 0,\r\n"
    "   ,,,,,,,,\r\n"
    "   0\r\n"
    "   ;   $ after the end\r\n"
    "[259_Extras]\r\n"
    "259_Ratio = .004, 1e3, +5, {1, 2, 3}, 12:00:00;\r\n"
    "$ closing comment\r\n"
).encode("latin-1")


#: A device none of our profiles describes: a flow controller of a made-up vendor, written by hand.
#: Class 0x70 holds its parameters (instance 1: setpoint, actual flow, valve, tag; instance 2: mode);
#: Param7 mirrors a standard Identity attribute. The heartbeat points are 197/196, not the usual
#: 198/199, and the RPI parameter allows 2 ms to 1 s.
GENERIC_EDS = """\
$ Acme FC-10 flow controller: hand-written for the cipstack tests
[File]
    DescText = "Acme FC-10 flow controller";
    CreateDate = 04-01-2024;
    CreateTime = 08:30:00;
    Revision = 1.2;

[Device]
    VendCode = 1234;
    VendName = "Acme Controls";
    ProdType = 0x2B;            $ generic device
    ProdTypeStr = "Generic Device";
    ProdCode = 77;
    MajRev = 3;
    MinRev = 14;
    ProdName = "Acme FC-10";
    Catalog = "FC-10";

[Device Classification]
    Class1 = EtherNetIP;

[Params]
    Param1 = 0, 6, "20 70 24 01 30 01", 0x0000, 0xC7, 2, "Flow Setpoint", "l/min", "Flow to hold",
        0, 500, 120, , , , , , , , , 0;
    Param2 = 0, 6, "20 70 24 01 30 02", 0x0030, 0xC3, 2, "Flow Actual", "l/min", "Measured flow",
        -100, 600, 0, , , , , , , , , 0;
    Param3 = 0, 6, "20 70 24 01 30 03", 0x0002, 0xC1, 1, "Valve Open", "", "",
        0, 1, 0, , , , , , , , , 0;
    Enum3 = 0, "Closed", 1, "Open";
    Param4 = 0, 6, "20 70 24 02 30 01", 0x0000, 0xC6, 1, "Mode", "", "0 off, 1 auto, 2 manual, 3 purge",
        0, 3, 1, , , , , , , , , 0;
    Param5 = 0, 6, "20 70 24 01 30 04", 0x0000, 0xDA, 12, "Tag", "", "Plant tag",
        , , "FC-10 North", , , , , , , , , 0;
    Param6 = 0, , , 0x0000, 0xC8, 4, "RPI", "us", "Requested packet interval",
        2000, 1000000, 20000, , , , , , , , , 0;
    Param7 = 0, 6, "20 01 24 01 30 07", 0x0010, 0xDA, 11, "Product Name", "", "",
        , , "Acme FC-10", , , , , , , , , 0;

[Assembly]
    Assem100 = "Control", "20 04 24 64 30 03", 4, 0x0000, , ,
        16, Param1,
        1, Param3,
        7, ,
        8, Param4;
    Assem101 = "Status", "20 04 24 65 30 03", 6, 0x0000, , ,
        16, Param2,
        16, Param1,
        1, Param3,
        15, ;
    Assem196 = "Listen Only Heartbeat", "20 04 24 C4 30 03", 0, 0x0000, , ;
    Assem197 = "Input Only Heartbeat", "20 04 24 C5 30 03", 0, 0x0000, , ;

[Connection Manager]
    Connection1 = 0x04010002, 0x44640405, Param6, 4, Assem100, Param6, 6, Assem101, , , , ,
        "Control", "Setpoint, valve and mode out; flow in", "20 04 24 01 2C 64 2C 65";
    Connection2 = 0x02010002, 0x44640305, Param6, 0, Assem197, Param6, 6, Assem101, , , , ,
        "Monitor", "Flow in, heartbeat out", "20 04 24 01 2C C5 2C 65";
    Connection3 = 0x01010002, 0x44240305, Param6, 0, Assem196, Param6, 6, Assem101, , , , ,
        "Listen", "Flow in, shared by multicast", "20 04 24 01 2C C4 2C 65";

[Capacity]
    MaxIOConnections = 4;
    MaxMsgConnections = 4;
"""

#: One construct per line that the emulator cannot serve, and what it says of each (a fragment
#: of the warning), with the keyword of the entry. Everything else in the file is served.
BROKEN_EDS = """\
[Device]
    VendCode = 1234;
    ProdType = 0x2B;
    MajRev = 1;
    MinRev = 0;
    ProdName = "Broken";

[Params]
    Param1 = 0, 6, "20 70 24 01 30 01", 0x0000, 0xC7, 2, "Good", "", "", 0, 10, 5, , , , , , , , , 0;
    Param2 = 0, 6, "20 70 24 01 30 02", 0x0000, 0xEE, 2, "Odd type", "", "", 0, 10, 5, , , , , , , , , 0;
    Param3 = 0, 8, "20 70 24 [Param1] 30 03", 0x0000, 0xC7, 2, "Path by param", "", "",
        0, 300, 5, , , , , , , , , 0;
    Param4 = 0, 4, "20 70 24 01", 0x0000, 0xC7, 2, "No attribute", "", "", 0, 10, 5, , , , , , , , , 0;
    Param5 = 0, 6, "20 70 24 01 30 05", 0x0000, 0xC7, 2, "Default too big", "", "",
        0, 10, 99, , , , , , , , , 0;
    Param6 = 0, 6, "20 70 24 01 30 06";
    Param7 = 0, 6, "20 01 24 01 30 63", 0x0000, 0xC7, 2, "No such Identity attribute", "", "",
        0, 10, 5, , , , , , , , , 0;
    Param8 = 0, 6, "20 70 24 01 30 08", 0x0000, 0xC6, 1, "Bad enum", "", "", 0, 3, 1, , , , , , , , , 0;
    Enum8 = 0, "Off", "On", 1;

[Assembly]
    Assem100 = "Variable", "20 04 24 64 30 03", Param99, 0x0000, , ;
    Assem101 = "Too few members", "20 04 24 65 30 03", 4, 0x0000, , , 16, Param1;
    Assem102 = "Not an assembly", "20 05 24 01", 2, 0x0000, , , 16, Param1;
    Assem103 = "Input", "20 04 24 67 30 03", 2, 0x0000, , , 16, Param1;

[Connection Manager]
    Connection1 = 0x00010008, 0x44640405, 10000, 2, Assem101, 10000, 2, Assem103, , , , ,
        "Class 3", "", "20 04 24 01 2C 65 2C 67";
    Connection2 = 0x08010002, 0x44640405, 10000, 4, Assem101, 10000, 2, Assem103, , , , ,
        "Redundant", "", "20 04 24 01 2C 65 2C 67";
    Connection3 = 0x04010002, 0x44640405, 10000, 4, Assem101, 10000, 4, , , , , ,
        "Unknown input", "", "20 04 24 01 2C 65 2C 67";
    Connection4 = 0x04010002, 0x44640405, 10000, 4, Assem101, 10000, 2, Assem103, , , , ,
        "Good", "", "20 04 24 01 2C 65 2C 67";
"""

#: (entry, fragment of its warning) for every construct of BROKEN_EDS the emulator skips.
BROKEN_WARNINGS = [
    ("[Device]", "[Device] ProdCode is missing"),
    ("Param2", "Param2: data type 0xEE"),
    ("Param3", "Param3: link path: path item [Param1]"),
    ("Param4", "Param4: link path 20 70 24 01: not a class/instance/attribute path"),
    ("Param5", "Param5: default 99"),
    ("Param6", "Param6 has 3 fields"),
    ("Param7", "Param7: the standard Identity object has no instance 1 attribute 99"),
    ("Enum8", "Enum8: a value/name pair is malformed"),
    ("Assem100", "Assem100: size Param99 is not a number of bytes, nor a ParamN with a default"),
    ("Assem101", "Assem101: members add up to 16 bits, not 32"),
    ("Assem102", "Assem102: path 20 05 24 01 is not an Assembly instance"),
    ("Connection1", "Connection1: transport 0x0008 is not class 1"),
    ("Connection2", "Connection2: redundant owner connections are not supported"),
    ("Connection3", "Connection3 (Unknown input): T->O size 4 but point 103 is 2 bytes: not offered"),
]
