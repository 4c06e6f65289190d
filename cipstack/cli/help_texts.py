"""What each command says about itself: the one line the command list shows, the description and
the examples its ``--help`` ends with. The parser takes them from here (``parser.build_parser``), so
the parser is the whole reference of the command line, and the documentation is generated from it.

An example is a command line as a user types it, and a few words on what it does; the tests parse
every example (up to a pipe or a redirection) with the parser it documents.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

#: Width of the description and examples (``--help`` wraps the options to the terminal itself).
WIDTH = 79


@dataclass(frozen=True)
class CommandText:
    help: str
    description: str
    examples: tuple[tuple[str, str], ...]

    def description_text(self) -> str:
        return "\n\n".join(textwrap.fill(paragraph, WIDTH) for paragraph in self.description.split("\n\n"))

    def epilog(self) -> str:
        lines = ["examples:"]
        for command, what in self.examples:
            lines.append(f"  {command}")
            lines.extend(textwrap.wrap(what, WIDTH, initial_indent=" " * 6, subsequent_indent=" " * 6))
        return "\n".join(lines)


PROGRAM = CommandText(
    "CIP for AC drives over EtherNet/IP and CompoNet",
    "CIP for AC drives over EtherNet/IP and CompoNet: an adapter emulator of the ACG drive and the "
    "Omron MX2/RX, discovery, explicit messaging and class 1 I/O against any target, EDS files and "
    "capture analysis.\n\n"
    "Every failure prints one line on stderr and exits non-zero: 2 for bad arguments (after the "
    "command's usage when the parser finds them), 1 for an error status or a network failure. A "
    "command whose output is cut short (cipstack ... | head) stops quietly with 141, as a process "
    "SIGPIPE ends. `cipstack COMMAND --help` describes a command and gives examples.",
    (("cipstack adapter --param drv=4 --param Frq=8",
      "run the emulated ACG drive on 127.0.0.1, run command and speed reference from the network"),
     ("cipstack identity 127.0.0.1", "who is there (ListIdentity)")),
)

#: By command path: ("get",), ("drive", "trip"), ("capture", "analyze").
COMMANDS: dict[tuple[str, ...], CommandText] = {
    ("adapter",): CommandText(
        "run the adapter emulator",
        "Run the adapter emulator: a software AC drive that answers EtherNet/IP explicit messages "
        "(UCMM and class 3) and class 1 I/O on --host and --port until Ctrl-C or SIGTERM. The device is "
        "the ACG drive with its ACG-ET2 card (ACG-ET2 manual) unless --profile names the Omron MX2 or RX with "
        "its CompoNet option board, or --eds the generic device an EDS file describes.\n\n"
        "Saved parameters persist in a state file; `cipstack drive` reaches the running emulator through "
        "its control socket. A status line goes to stdout, the log to stderr.",
        (("cipstack adapter --param drv=4 --param Frq=8",
          "the ACG, taking its run command and speed reference from the network"),
         ("cipstack adapter --host 127.0.0.2 --profile mx2 --model MX2-A2015-E",
          "an Omron MX2 on a second loopback address"),
         ("cipstack adapter --profile mx2 --param A004=60 --param P044=1.5",
          "an MX2 set on its Digital Operator: maximum frequency 60.0 Hz, network error timer 1.5 s"),
         ("cipstack adapter --modbus-port 5020 --max-sessions 8",
          "also serve Modbus TCP on port 5020, at most 8 encapsulation sessions")),
    ),
    ("fleet",): CommandText(
        "emulate many devices at once, each on its own address",
        "Emulate many devices at once, each an adapter on its own address (any 127.x address works on "
        "Linux's loopback), from --device groups or a TOML --spec file. Each device keeps its own state "
        "file and control socket (`cipstack drive ... --host ADDRESS`); --workers spreads the devices "
        "over processes; --http serves one HTTP control API for every device of every worker, by "
        "address (/devices/ADDRESS/...); --shard serves one part of a plant spec, the same on every "
        "machine.",
        (("cipstack fleet --addresses 127.0.0.10-127.0.0.13 --device 'acg*3' --device mx2:MX2-A2015-E",
          "three ACG drives and one MX2 on 127.0.0.10 to 127.0.0.13"),
         ("cipstack fleet --addresses 127.0.0.10-127.0.0.73 --device 'acg*64' --workers 2",
          "64 ACG drives over two processes"),
         ("cipstack fleet --addresses 127.0.0.10-127.0.0.73 --device 'acg*64' --workers 2 --http 127.0.0.1:8080",
          "the same, with one HTTP API for all: curl http://127.0.0.1:8080/devices"),
         ("cipstack fleet --spec plant.toml --shard 1/3",
          "the second of three shards of one plant spec (one per machine or Kubernetes pod)"),
         ("cipstack fleet --addresses 127.0.0.10-127.0.0.13 --device 'acg*4' --security lab",
          "each device also serves TLS and DTLS (CIP Security) on port 2221 of its address")),
    ),
    ("plant",): CommandText(
        "one HTTP API for every device of a plant's fleets, on many machines or pods",
        "Serve one HTTP control API for every device of every fleet (`cipstack fleet --http`) that "
        "--fleet names: a DNS name whose A records are every fleet, such as a Kubernetes headless "
        "Service, with the port of their APIs. It looks again every --refresh: a new fleet is added, "
        "one that does not answer or is gone from the records is listed with its devices' error, "
        "which answer 503. Its token (--http-token...) is also the one it sends to the fleets.",
        (("cipstack plant --fleet cipstack-fleet:8080 --http 0.0.0.0:8080 --http-allow-remote "
          "--http-token-file token",
          "the plant view of a Kubernetes StatefulSet's fleets (deploy/)"),
         ("cipstack plant --fleet 127.0.0.1:8081 --fleet 127.0.0.1:8082 --http 127.0.0.1:8080",
          "two fleets on one machine, one API")),
    ),
    ("models",): CommandText(
        "the device families installed and their models",
        "List every device family installed (cipstack's own and those other packages bring by the "
        "cipstack.devices entry point) and its models: profile, model, product code, product name, EDS file "
        "name and the distribution that brought it; a family of one model is one line. A family whose "
        "plug-in cannot be loaded is reported on stderr (exit status 1).",
        (("cipstack models --profile mx2", "the MX2 models"),
         ("cipstack models --json", "every model, one JSON object per line")),
    ),
    ("componet",): CommandText(
        "run a CompoNet network of MX2/RX slaves behind an EtherNet/IP gateway",
        "Run a CompoNet network of MX2/RX slaves behind an EtherNet/IP gateway: explicit messages reach "
        "a slave routed through the gateway's CompoNet port 2 to its node address (`get --route 2/NODE`); "
        "the master's OUT and IN words are assembly instances of the gateway.",
        (("cipstack componet --nodes mx2:MX2-A2015-E@3,rx:RX-A4055-E@5",
          "an MX2 at node 3 and an RX at node 5"),
         ("cipstack get 127.0.0.1 1/1/7 --route 2/3", "then: the product name of the slave at node 3")),
    ),
    ("discover",): CommandText(
        "ListIdentity over UDP",
        "Send ListIdentity over UDP (to the broadcast addresses, or to --broadcast) and print each "
        "device that answers within --timeout: address, product name, vendor, device type, product "
        "code, revision, serial number, status and state. With --security, ListIdentity goes in a DTLS "
        "session with each device --broadcast names (a broadcast cannot be secured), and a device that "
        "refuses it or does not answer is one line on stderr and exit status 1.",
        (("cipstack discover", "every device on every interface, loopback included"),
         ("cipstack discover --broadcast 127.255.255.255 --json", "loopback only, one JSON object a device"),
         ("cipstack discover --broadcast 192.168.1.20,192.168.1.21 --security lab",
          "two devices, each over DTLS on UDP 2221 (CIP Security)")),
    ),
    ("identity",): CommandText(
        "ListIdentity over TCP",
        "Ask one target who it is (ListIdentity over TCP): vendor, device type, product code, revision, "
        "serial number, status, state and product name.",
        (("cipstack identity 127.0.0.1", "the emulator started by `cipstack adapter`"),
         ("cipstack identity 127.0.0.2:44818 --json", "as one JSON object"),
         ("cipstack identity 192.168.1.20 --security lab", "over TLS on port 2221 (CIP Security)")),
    ),
    ("get",): CommandText(
        "Get_Attribute_Single (or Get_Attributes_All without an attribute)",
        "Read an attribute with Get_Attribute_Single, or every attribute of an instance with "
        "Get_Attributes_All when the path has no attribute. Unconnected (UCMM) unless --connected opens "
        "a class 3 connection; --route sends it on through the target (Unconnected_Send). The value is "
        "decoded by what the device's profile declares, or as --type.",
        (("cipstack get 127.0.0.1 1/1/7", "the Identity's Product Name"),
         ("cipstack get 127.0.0.1 0x2A/1/102 --connected", "the ACG's acceleration time, over class 3"),
         ("cipstack get 127.0.0.1 0xF5/1/13 --type UINT --json", "a raw attribute as UINT, in JSON"),
         ("cipstack get 192.168.1.20 1/1/7 --security lab",
          "over TLS on port 2221 (CIP Security), with lab's CA and client certificate")),
    ),
    ("set",): CommandText(
        "Set_Attribute_Single",
        "Write an attribute with Set_Attribute_Single. VALUE is the raw value, as on the wire (decimal or "
        "0x hex for integers, true/false/on/off for a BOOL, text for strings), unless --scaled: then it is "
        "the engineering value, turned into raw steps by the attribute's declaration. The type is the "
        "declaration's (the device's profile, or --eds FILE), else --type. A refused value prints the "
        "general and extended status.",
        (("cipstack set 127.0.0.1 0x2A/1/102 7.5 --scaled",
          "the ACG's acceleration time to 7.5 s (75 steps of 0.1 s)"),
         ("cipstack set 127.0.0.1 0x29/1/3 on", "the ACG's Forward Run Cmd. (a BOOL) on"),
         ("cipstack set 127.0.0.1 0xF5/1/13 120 --connected",
          "the encapsulation inactivity timeout to 120 s, over class 3"),
         ("cipstack set 127.0.0.1 0x99/1/1 5 --type UINT", "an attribute nothing declares, as UINT")),
    ),
    ("params",): CommandText(
        "drive parameter recipes: dump, load, diff (TOML files)",
        "Drive parameter recipes: every parameter the device's profile (or --eds FILE) declares, with its "
        "code, name, raw and engineering value and unit, in a TOML file; written back to another drive, "
        "or compared with one.",
        (("cipstack params dump 127.0.0.1 -o drive.toml", "the drive's parameters to drive.toml"),
         ("cipstack params load 127.0.0.2 drive.toml", "the same parameters into a second drive, saved")),
    ),
    ("params", "dump"): CommandText(
        "write every declared parameter to a TOML file",
        "Read every parameter the device's profile (or --eds FILE) declares and write it to a TOML recipe "
        "(standard output without -o): code, name, path, raw value, and the engineering value and unit "
        "for the reader.",
        (("cipstack params dump 127.0.0.1 -o drive.toml", "the ACG's 409 parameters to drive.toml"),),
    ),
    ("params", "load"): CommandText(
        "write a recipe's parameters that differ, then save",
        "Write the settable parameters of a recipe whose value on the device differs, in a safe order (the "
        "ones that bound the others first: Max Freq on the ACG), then save them where the device has a "
        "save command (the ACG's 0x03E0). Refused while the drive runs unless --force; a value the device "
        "refuses is reported and the rest written (exit status 1).",
        (("cipstack params load 127.0.0.1 drive.toml", "load and save"),
         ("cipstack params load 127.0.0.1 drive.toml --force --no-save",
          "load while the drive runs, without saving")),
    ),
    ("params", "diff"): CommandText(
        "the recipe's parameters whose value on the device differs",
        "Compare a recipe with the device: one line per parameter whose value differs, the device's and the "
        "file's, each as engineering value and raw value. Exit status 1 when any differs, as diff's.",
        (("cipstack params diff 127.0.0.1 drive.toml", "what changed on the drive since the dump"),),
    ),
    ("io",): CommandText(
        "open a class 1 connection, print input changes by field name",
        "Open a class 1 (I/O) connection with a Forward_Open, send the output assembly at the RPI, print "
        "each change of the input by field name, and close the connection (Forward_Close) after "
        "--duration or on Ctrl-C, then print its statistics. The assemblies come from --output/--input "
        "or from a ConnectionN of an EDS file; --list-fields shows their fields and the unit of a raw "
        "value, which is what --set takes.",
        (("cipstack io 127.0.0.1 --output 21 --input 71 --set run_forward=1 --set speed_reference=900",
          "run the ACG forward at 900 rpm (30 Hz on its 4-pole motor) for 5 s"),
         ("cipstack io 127.0.0.1 --output 101 --input 111 --list-fields",
          "the fields of 101/111: their speed words are in 0.01 Hz (3000 is 30.00 Hz)"),
         ("cipstack io 127.0.0.1 --eds ACG-ET2_1.01.eds --connection 1 --print every:1s --duration 10s",
          "the EDS file's first connection, the latest input once a second")),
    ),
    ("drive",): CommandText(
        "control a running emulator: inject a trip, read its status",
        "Control a running emulator through its local control socket (not a CIP object): trip it, "
        "inject and clear faults (lost I/O, refused Forward_Opens, an unplugged cable, a power cycle...), "
        "or read its status line and its active faults. The socket is found by the emulator's --host and "
        "--port, or given with --control.",
        (("cipstack drive status", "the status of the emulator on 127.0.0.1:44818"),
         ("cipstack drive trip OverHeat --host 127.0.0.11", "trip one device of a fleet"),
         ("cipstack drive fault stop-producing --for 5s", "the drive's T->O I/O stops for 5 s")),
    ),
    ("drive", "trip"): CommandText(
        "trip the emulated drive with a fault code",
        "Trip the emulated drive with a fault code of its manual (the ACG's Drive Fault Codes, the "
        "MX2/RX's trip codes) or its name, as a real fault would: the drive stops and reports it until "
        "a fault reset.",
        (("cipstack drive trip 0x4200", "OverHeat on the ACG"),
         ("cipstack drive trip E05 --port 44819", "overload on the MX2 emulated on port 44819")),
    ),
    ("drive", "fault"): CommandText(
        "inject a fault into the running emulator, or clear faults",
        "Inject a fault between the wire and the emulated device: class 1 (stop-producing, drop, duplicate, "
        "reorder, delay, freeze-sequence, wrong-size, ignore-output, idle), explicit messaging "
        "(delay-replies, error-status, refuse-forward-open, close-tcp, drop-sessions) or the whole device "
        "(unplug, plug, power-cycle) or its CIP Security (expire-certificate, revoke-certificate, "
        "refuse-cipher-suite, drop-dtls-records). A lasting fault stays until `cipstack drive fault clear` or for "
        "--for DURATION; after it is cleared the device is what it would have been.",
        (("cipstack drive fault stop-producing --for 2s", "the scanner's class 1 connection times out"),
         ("cipstack drive fault refuse-forward-open 0x0113 --count 2", "the next two Forward_Opens refused"),
         ("cipstack drive fault drop-dtls-records --share 0.5 --for 10s", "half the DTLS records lost"),
         ("cipstack drive fault clear", "clear every active fault")),
    ),
    ("drive", "faults"): CommandText(
        "the faults active in the running emulator",
        "List the faults active in the running emulator: id, name, options, when applied and the time "
        "left of one applied --for a while.",
        (("cipstack drive faults", "the emulator on 127.0.0.1:44818"),
         ("cipstack drive faults --json", "as JSON")),
    ),
    ("drive", "status"): CommandText(
        "the emulated drive's status line",
        "Print the emulated drive's status line: drive state, direction, output and reference "
        "frequency, the power and the link when they are off or unplugged, connections, and the trip if "
        "there is one. With --json: the same fields, with power (on/off) and link (plugged/unplugged).",
        (("cipstack drive status", "the emulator on 127.0.0.1:44818"),
         ("cipstack drive status --host 127.0.0.12 --json", "a fleet device's status as JSON")),
    ),
    ("drive", "reset"): CommandText(
        "reset the emulated drive's trip",
        "Reset the trip of the emulated drive, as its manual's fault reset does: the ACG's Drive Fault "
        "Reset (a level-type trip holds while its cause lasts: refused, exit 1), the MX2/RX Digital "
        "Operator's STOP/RESET key.",
        (("cipstack drive reset", "after `cipstack drive trip OverHeat`"),),
    ),
    ("drive", "clear"): CommandText(
        "clear active faults",
        "Clear every active fault of the running emulator, or one by its id, or all of one name (as "
        "`cipstack drive fault clear`). A power-cycle still off gets its power back.",
        (("cipstack drive clear", "every active fault"), ("cipstack drive clear 3", "fault 3")),
    ),
    ("drive", "parameter"): CommandText(
        "read a keypad parameter",
        "Read a keypad parameter of the emulated drive by its code (the ACG's drv, ACC, CM.23; an MX2/RX "
        "function code F001, A004, P044): its value in the keypad's unit, its raw value and address.",
        (("cipstack drive parameter ACC", "the ACG's acceleration time"),
         ("cipstack drive parameter A004 --port 44819 --json", "an MX2's base frequency, as JSON")),
    ),
    ("drive", "set-parameter"): CommandText(
        "set a keypad parameter",
        "Set a keypad parameter of the emulated drive now, in the keypad's unit, as on its keypad (not "
        "saved: a power cycle loses it). Refused with the device's reason (read-only, not while running, "
        "the power off).",
        (("cipstack drive set-parameter ACC 2.5", "the ACG's acceleration time, 2.5 s"),),
    ),
    ("drive", "events"): CommandText(
        "what happened in the emulator",
        "Print the events the emulator kept (connections, run/idle, drive states and trips, parameter "
        "writes, faults) after event number --since, oldest first, at most 1000.",
        (("cipstack drive events", "every event kept"), ("cipstack drive events --since 40 --json", "as JSON")),
    ),
    ("drive", "power"): CommandText(
        "cycle the emulated device's power",
        "Cycle the power of the emulated device (the power-cycle fault): every port closes and the RS-485 "
        "line is silent for --off, then everything opens once; what was not saved is lost. Answers within "
        "2 s, while the power may still be off.",
        (("cipstack drive power cycle --off 2s", "off for 2 s"),),
    ),
    ("drive", "link"): CommandText(
        "unplug or plug the emulated device's Ethernet cable",
        "Unplug the Ethernet cable (every Ethernet port closed, class 1 connections time out, RS-485 goes "
        "on) or plug it back (the unplug and plug faults).",
        (("cipstack drive link unplug", "pull the cable"), ("cipstack drive link plug", "plug it back")),
    ),
    ("drive", "parameters"): CommandText(
        "every keypad parameter, group by group",
        "Print every keypad parameter of the emulated drive, group by group as its manual lists them: code, "
        "name, value in the keypad's unit, range and whether it is writable (what the front panel shows).",
        (("cipstack drive parameters", "the ACG's groups"), ("cipstack drive parameters --json", "as JSON")),
    ),
    ("drive", "connections"): CommandText(
        "every session and connection, with its data",
        "Print the sessions, class 3 and class 1 connections of the emulator; each class 1 connection with "
        "its RPIs, counters, run/idle and the data of both directions by field names (hex where the "
        "assembly names none).",
        (("cipstack drive connections", "what holds the drive now"),),
    ),
    ("drive", "fault-table"): CommandText(
        "every fault the emulator can be given",
        "Print every fault of the fault table with where it acts and its options (what `cipstack drive "
        "fault` and the front panel's fault forms take).",
        (("cipstack drive fault-table", "the faults and their options"),),
    ),
    ("drive", "trips"): CommandText(
        "the trips the drive's manual lists",
        "Print the trips `cipstack drive trip` takes: the ACG's Drive Fault Codes table by name, the MX2/RX "
        "trip codes of its table, each with its CIP fault code.",
        (("cipstack drive trips", "what `cipstack drive trip` takes"),),
    ),
    ("security",): CommandText(
        "CIP Security: credentials for EtherNet/IP over TLS",
        "CIP Security (EtherNet/IP over TLS on TCP 2221): make the folder of credentials that "
        "`cipstack adapter --security DIR` serves with and a scanner connects with, or configure a "
        "factory-default device over the network with them.",
        (("cipstack security init lab", "a lab CA, the device's and the client's certificates and keys in lab/"),
         ("cipstack security configure 192.168.1.20 --security lab", "configure a device over the network")),
    ),
    ("security", "init"): CommandText(
        "make a lab CA, device and client certificates, or a PSK",
        "Write a lab certificate authority (ca.pem), the device's certificate and key (device.pem, "
        "device.key) and the client's, that is the originator's (client.pem, client.key): ECDSA P-256 "
        "keys, certificates signed with SHA-256, keys mode 0600, and the CA's key (ca.key, mode 0600) that "
        "signs a device's request in `cipstack security configure`. With --psk, a pre-shared key file "
        "(psk.txt, one line IDENTITY:HEX, mode 0600) as well, which both roles then offer in TLS 1.2 and "
        "DTLS 1.2 handshakes (the PSK suites); with --psk-only, that file alone. A file "
        "already there is kept unless --force is given.",
        (("cipstack security init lab", "the lab CA and both key pairs in lab/"),
         ("cipstack security init lab --psk --force", "the same, and a pre-shared key, replacing what is there")),
    ),
    ("security", "configure"): CommandText(
        "configure a factory-default device's CIP Security over the network",
        "The push model of a configuration tool, over plain EtherNet/IP: Begin_Config, Create_CSR on the "
        "device (its request read from the File object), the lab CA of DIR signs it, the CA and device "
        "certificates downloaded into their File object instances and the trust written, DIR's psk.txt "
        "(if any) written as the Pre-Shared Keys, Verify_Certificate, Apply_Config; then the device is "
        "read over TLS on --security-port "
        "to check it serves the certificate just written. A step the device refuses aborts the session "
        "and is named in one line.",
        (("cipstack security configure 192.168.1.20 --security lab", "configure the device with lab's CA"),
         ("cipstack security configure 127.0.0.1:44818 --security lab --common-name drive-7",
          "the device certificate named drive-7")),
    ),
    ("eds",): CommandText(
        "EDS files: generate, check, show, fetch",
        "Electronic Data Sheets: write the EDS files of the emulated models, check EDS files from "
        "anywhere against the rules a configuration tool relies on, summarize one, or fetch the one a "
        "device carries from its File object.",
        (("cipstack eds generate --profile acg -o eds", "the ACG-ET2's EDS file into eds/"),
         ("cipstack eds check eds/ACG-ET2_1.01.eds", "check a file"),
         ("cipstack eds fetch 127.0.0.1 -o device.eds", "the EDS file the device at 127.0.0.1 carries")),
    ),
    ("eds", "check"): CommandText(
        "check EDS files against the rules a configuration tool relies on",
        "Check EDS files against the rules a configuration tool relies on (syntax, required entries, "
        "parameters, assemblies, connections); each finding is one line with the file and line number. "
        "With --against, also compare [Device] with a live device's Identity. Exits 1 on an error.",
        (("cipstack eds check eds/*.eds", "every file of a directory"),
         ("cipstack eds check eds/ACG-ET2_1.01.eds --against 127.0.0.1", "and the device it describes"),
         ("cipstack eds check eds/ACG-ET2_1.01.eds --against 192.168.1.20 --security lab",
          "the same over TLS, its class 1 connections over DTLS (CIP Security)")),
    ),
    ("eds", "generate"): CommandText(
        "write the EDS files of emulated models",
        "Write the EDS file of an emulated model, or of every model of a family's table, from the same "
        "declarations the emulator serves.",
        (("cipstack eds generate --profile acg -o eds", "the ACG-ET2's file"),
         ("cipstack eds generate --profile mx2 --all -o eds", "every MX2 model's file")),
    ),
    ("eds", "fetch"): CommandText(
        "read a device's own EDS file from its File object",
        "Read the EDS file a device carries, from its File object (class 0x37, instance 0xC8, \"EDS and "
        "Icon Files\") with Initiate_Upload and Upload_Transfer, check its size and checksum, and write "
        "it (uncompressed when the device serves it compressed). The emulators serve theirs.",
        (("cipstack eds fetch 127.0.0.1 -o device.eds", "the emulator's EDS file"),
         ("cipstack eds fetch 192.168.1.20:44818 -o - | cipstack eds show /dev/stdin", "straight to a summary")),
    ),
    ("eds", "show"): CommandText(
        "a readable summary: identity, assemblies, connections",
        "Print a readable summary of an EDS file: its identity, parameters by group, assemblies with "
        "their members, and connections.",
        (("cipstack eds show eds/ACG-ET2_1.01.eds", "the ACG-ET2's file"),
         ("cipstack eds show eds/ACG-ET2_1.01.eds --json", "as one JSON object")),
    ),
    ("capture",): CommandText(
        "analyse a pcap/pcapng capture of EtherNet/IP and CIP traffic",
        "Analyse a pcap or pcapng capture of EtherNet/IP and CIP traffic.",
        (("cipstack capture analyze traffic.pcapng", "what happened on the wire"),),
    ),
    ("capture", "analyze"): CommandText(
        "explicit exchanges, class 1 connection timing, anomalies",
        "Explain a pcap or pcapng capture in the device's own words: every explicit exchange with its "
        "attribute names and decoded values, each class 1 connection's timing (RPI, API, inter-arrival "
        "percentiles, late, lost and duplicate packets) and data changes, and anomalies. Targets are "
        "decoded by the profile of their identity, or by --profile or --eds.",
        (("cipstack capture analyze traffic.pcapng", "the summary"),
         ("cipstack capture analyze traffic.pcapng --json --no-progress", "every record as JSON lines"),
         ("cipstack capture analyze traffic.pcapng --connection 1 --csv timing",
          "connection 1's timing rows into timing/")),
    ),
    ("conform",): CommandText(
        "run the conformance battery against an EtherNet/IP target",
        "Run the conformance battery against any EtherNet/IP target and report, check by check, what it "
        "does against what the specification (and, with --eds, its EDS file) expects: the request sent, "
        "the reply, the reference and a verdict (pass, fail, warning, n/a, or not run when it needs an "
        "--allow-* option not given or the target stopped answering before it: the check after which "
        "it went silent is named and the run stops). Groups: encap "
        "(encapsulation), router (message router and errors), objects (required objects), cm (Connection "
        "Manager Forward_Open matrix), class1 (class 1 behaviour), eds (EDS against the device), profile "
        "(the AC drive profile's assemblies and attributes; with --allow-motion also its motion: run forward, "
        "stop, fault reset, NetCtrl/NetRef and idle, over a class 1 connection of assemblies 20/21 and "
        "70/71, within the drive's own acceleration and deceleration times), and "
        "final (the device as found: run after every run that opened a connection or wrote). cm and "
        "class1 take their connection points from --eds; without it from --connection-points, the "
        "device's own EDS file (File object), --eds-dir, the AC drive profile or bounded probing of its "
        "assemblies, and say which.\n\n"
        "Safe by default: nothing is written without --allow-writes, the device is not reset without "
        "--allow-reset, the motor is not run without --allow-motion (the drive is stopped and its "
        "NetCtrl/NetRef and speed reference restored after each motion check, whatever happens), the "
        "checks that exhaust the device's resources on purpose (encap.session_limit: 40 sessions at once) "
        "do not run without --allow-stress, requests are rate-bounded, every connection opened is closed "
        "on a live session and every write is written back. Exit status 0 when no check fails, 1 when one "
        "fails, 2 for bad arguments or a target that is unreachable or does not speak EtherNet/IP; with --strict a "
        "warning counts as a failure.",
        (("cipstack conform 127.0.0.1", "every group, the connection points found on the device"),
         ("cipstack conform 192.168.1.20 --eds drive.eds --junit conform.xml --html conform.html",
          "all six groups, with a JUnit file for CI and a page to attach to a test report"),
         ("cipstack conform 127.0.0.1:44818 --only encap,router --json", "two groups, as one JSON object"),
         ("cipstack conform 127.0.0.1 --only profile --allow-motion",
          "the AC drive profile, running the motor: only with the machine safe to move")),
    ),
    ("completion",): CommandText(
        "print the shell completion script for bash or zsh",
        'Print the completion script of cipstack for bash or zsh, generated from this command line by '
        'shtab (install it with pip install "cipstack[completion]").',
        (("cipstack completion bash > ~/.local/share/bash-completion/completions/cipstack",
          "bash: completion in every new shell"),
         ("cipstack completion zsh > ~/.zfunc/_cipstack",
          "zsh: with ~/.zfunc in fpath before compinit in ~/.zshrc")),
    ),
}

__all__ = ["COMMANDS", "PROGRAM", "CommandText"]
