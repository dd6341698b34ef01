"""An executor of the SPEL+ subset the station's Epson program uses, written from Epson's own
documents, so that the tests run ``robot-programs/epson/StationLink.prg`` unchanged, as an Epson
RC700 / RC90 controller with background tasks enabled runs it (issue 43).

Sources (each module cites its own): SPEL+ Language Reference and Epson RC+ User's Guide pages
as listed under SOURCES in StationLink.prg ([REF-GLOBAL], [REF-TASKINFO], [REF-TILL], [REF-JA],
[UG-TYPES], [UG-BG], [TCP-14.3]); Epson's own SPEL+ code in the public RC+ extension samples
([EPSON-MODBUS]: Epson-Robots/rcplus-extensions, samples/rcplus-custom/VanguardModelPFScrewdriver/
VanguardModelPFScrewdriver/Libraries/Source/VGD_PF/Modbus.prg, a Modbus TCP client).

Modules: :mod:`.spel` (lexer, parser, build checks), :mod:`.check` (name checks), :mod:`.interp`
(types, tasks, errors), :mod:`.controller` (arm, TCP/IP ports, motion, the wall-clock pacing).
A construct the subset does not know is a build or run-time error, never skipped.
"""
