"""Defects the simulated Cougar can be told to have, so the conformance suite can be shown to catch them.

:class:`CougarFault` is the registry: each switch declared once, with what it breaks and the clauses it
breaks (the one record of every implementation's switches, :class:`manip.spec.faults.FaultSwitch`).  A
switch is named in :attr:`manip.cougar.CougarConfig.faults` (``manip-cougar --cougar-fault NAME``,
``manip-conform run --cougar sim --cougar-fault NAME``).  The simulator never tests a switch: it is given
the behaviours they choose as values, :class:`CougarDefects` (from its configuration) and, for the
``link-*`` ones, its end of the DRV-11J link :class:`LinkDefects` (:class:`manip.cougar.link.CougarEnd`
and ``manip-cougar``'s server, given the faults by ``serve_cougar``).  A clean Cougar has none; the
mutation test (``tests/conformance/cougar/test_cougar.py``) runs the Cougar cases against each fault and
requires its case to fail on one of the clauses it breaks.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from manip.spec.faults import FaultSwitch, defect

__all__ = ["CougarDefects", "CougarFault", "LinkDefects", "cougar_defects", "link_defects", "parse_faults"]


class CougarFault(FaultSwitch):
    """The simulated Cougar's fault switches, each declared once (where it acts, in brackets)."""

    WRONG_VERSION_CODE = defect(
        "wrong-version-code",
        "VERS is answered with response code 3 instead of 8 (CougarSim._version)",
        "cougar.vers.reply",
        caught_by=("cougar.reply.version",),
    )
    NO_OUT_OF_SYNC = defect(
        "no-out-of-sync",
        "an unknown command code dumps the buffer but sends no out-of-sync message (CougarSim._comint_run)",
        "cougar.comint.unknown-code",
        caught_by=("cougar.comint.unknown-code",),
    )
    GUARD_TRIPS_TWICE = defect(
        "guard-trips-twice",
        "a tripped guard stays armed for one more trip (CougarSim._guardm)",
        "cougar.guard-trips-once",
        caught_by=("cougar.guard.trips-once",),
    )
    FORCES_WRONG_SIGN = defect(
        "forces-wrong-sign",
        "the conversion drops the -1: forces are the load on the hand, not the force the robot applies "
        "(CougarSim._convert)",
        "cougar.nfv-conversion",
        caught_by=("cougar.forces.conversion",),
    )
    EXMN_WRONG_COUNT = defect(
        "exmn-wrong-count",
        "EXMN retrieves one word fewer than asked (CougarSim._exp)",
        "cougar.exmn.reply",
        caught_by=("cougar.reply.exmn",),
    )
    COMINT_EXECUTES_PARTIAL = defect(
        "comint-executes-partial",
        "COMINT runs a command whose data words have not all arrived, the missing ones taken as 0 "
        "(Comint.take)",
        "cougar.comint.partial-waits",
        caught_by=("cougar.comint.partial-waits",),
    )
    IGNORES_GUARDC = defect(
        "ignores-guardc",
        "GUARDC leaves the guard armed (CougarSim._guardc)",
        "cougar.guardc",
        caught_by=("cougar.guard.clear",),
    )
    RST_IGNORED = defect(
        "rst-ignored",
        "RST leaves the velocities as they were (CougarSim._resetw)",
        "cougar.rst",
        caught_by=("cougar.rst.zeroes-velocities",),
    )
    NPR_IGNORES_K = defect(
        "npr-ignores-k",
        "the compliance equation leaves out the spring term K (CougarSim._newpr)",
        "cougar.npr.reply",
        caught_by=("cougar.npr.gains",),
    )
    FILTER_CON_SWAPPED = defect(
        "filter-con-swapped",
        "FILTER weighs the filtered value with con4 and the sample with con3 (CougarSim._newpr)",
        "cougar.filter",
        caught_by=("cougar.filter.output",),
    )
    GRAVITY_FIXED_ORIENTATION = defect(
        "gravity-fixed-orientation",
        "GRAVITY takes the hand to be at READY whatever angles SEN or NPR sent (CougarSim._gravity)",
        "cougar.gravity",
        caught_by=("cougar.gravity.point-mass",),
    )
    GRAVITY_IGNORES_CG = defect(
        "gravity-ignores-cg",
        "GRAVITY corrects the force of the weight but not its torque about the centre of gravity "
        "(CougarSim._gravity)",
        "cougar.gravity",
        caught_by=("cougar.gravity.point-mass",),
    )
    NFV_KEEPS_GRAVITY = defect(
        "nfv-keeps-gravity",
        "NFV rewrites the conversion matrix but leaves the gravity model about the old compliance centre "
        "(CougarSim._newfv)",
        "cougar.nfv-conversion",
        caught_by=("cougar.gravity.nfv-redoes-model",),
    )
    NB_TRANSPOSED = defect(
        "nb-transposed",
        "NPR reads NB's 36 elements column after column instead of row after row (CougarSim._newpr)",
        "cougar.nb-row-order",
        caught_by=("cougar.npr.damping-matrix",),
    )
    JACOBIAN_TRANSPOSE_NOT_STORED = defect(
        "jacobian-transpose-not-stored",
        "JACOB stores J again where its transpose belongs, after J (Jacob._encode)",
        "cougar.jacob-transpose",
        caught_by=("cougar.jacob.transpose-stored",),
    )
    FILTER_TRUNCATES_TERMS = defect(
        "filter-truncates-terms",
        "ADC8 shifts each term of the sum right by 3 before adding, so a constant input settles up to 7 "
        "counts low (CougarSim._adc8)",
        "cougar.adc8-filter",
        caught_by=("cougar.adc8.integer-filter",),
    )
    GUARDS_SENSED_FORCE = defect(
        "guards-sensed-force",
        "GUARDM tests the sensed force, before GRAVITY's correction (CougarSim._guardm)",
        "cougar.guard-corrected-force",
        caught_by=("cougar.guard.gravity-corrected", "cougar.gravity.point-mass"),
    )
    COMPLIANCE_SENSED_FORCE = defect(
        "compliance-sensed-force",
        "NPR's compliance equation uses the sensed force, before GRAVITY's correction (CougarSim._newpr)",
        "cougar.compliance-corrected-force",
        caught_by=("cougar.gravity.compliance-corrected",),
    )
    NPR_IGNORES_FC = defect(
        "npr-ignores-fc",
        "the compliance equation leaves out the commanded force NFC (CougarSim._newpr)",
        "cougar.npr.reply",
        "cougar.compliance-corrected-force",
        caught_by=("cougar.gravity.compliance-corrected",),
    )
    NBJI_FIRST_ONLY = defect(
        "nbji-first-only",
        "the compliance equation scales every joint by NBJI's first element, not each by its own "
        "(Jacob.step)",
        "cougar.npr.reply",
        caught_by=("cougar.npr.gains",),
    )
    RRAW_LESS_OFFSETS = defect(
        "rraw-less-offsets",
        "RRAW reports the readings with the gauge offsets subtracted, not the gauges as read "
        "(CougarSim._reraw)",
        "cougar.rraw.before-offsets",
        caught_by=("cougar.rraw.before-offsets",),
    )
    LINK_SKIPS_BAD_FRAMES = defect(
        "link-skips-bad-frames",
        "the DRV-11J link drops a frame it cannot decode (a bad HELLO, an unknown type, a TICK of the "
        "wrong length) and carries on (FrameDecoder.feed, for CougarEnd)",
        "link.drv11j.bad-frame-ends",
        caught_by=("cougar.link.unknown-type", "cougar.link.bad-hello", "cougar.link.short-tick"),
    )
    LINK_IGNORES_WRONG_SIDE = defect(
        "link-ignores-wrong-side",
        "the link takes a HELLO naming the Cougar's own role and ignores frames only Cougar sends "
        "(COUGAR, TICKED) instead of ending (CougarEnd)",
        "link.drv11j.bad-frame-ends",
        caught_by=("cougar.link.wrong-side", "cougar.link.hello-wrong-role"),
    )
    LINK_TICK_BACKWARDS_RUNS = defect(
        "link-tick-backwards-runs",
        "a TICK earlier than the one before it runs at the earlier tick's time instead of ending the link "
        "(CougarEnd._model_time)",
        "link.drv11j.tick-backwards",
        caught_by=("cougar.link.tick-backwards",),
    )
    LINK_HELLO_OPTIONAL = defect(
        "link-hello-optional",
        "the link takes a first frame that is not HELLO as if HELLO had come before it (_End._greeted)",
        "link.drv11j.hello-first",
        caught_by=("cougar.link.not-hello-first",),
    )
    LINK_IGNORES_VERSION = defect(
        "link-ignores-version",
        "the link takes a HELLO of any version, not only 1 (_End._greeted)",
        "link.drv11j.hello-version",
        caught_by=("cougar.link.hello-other-version",),
    )
    LINK_IGNORES_BYE = defect(
        "link-ignores-bye",
        "the link carries on after the Puma's BYE (CougarEnd, _End._frames)",
        "link.drv11j.bye",
        caught_by=("cougar.link.bye",),
    )
    LINK_BUSY_SERVES_SECOND = defect(
        "link-busy-serves-second",
        "a second Puma connecting while one is linked is served too, not sent BYE 'busy' "
        "(CougarServer._handle)",
        "link.drv11j.busy",
        caught_by=("cougar.link.busy",),
    )
    RFRC_NTD_CODE = defect(
        "rfrc-ntd-code",
        "RFRC's six floats go out under NTD's response code 1, not 5 (the send copied from NPR's; "
        "CougarSim._rfr)",
        "cougar.rfrc.reply",
        caught_by=("cougar.reply.forces",),
    )
    RRAW_SEVEN_GAUGES = defect(
        "rraw-seven-gauges",
        "RRAW's loop stops one gauge short: code 9 and seven words (CougarSim._reraw)",
        "cougar.rraw.reply",
        "cougar.response.layout",
        caught_by=("cougar.reply.raw",),
    )
    RRAW_UNSIGNED = defect(
        "rraw-unsigned",
        "RRAW sends each reading as the converter's 12-bit code, not sign-extended: a negative reading "
        "comes as 4096 more (CougarSim._reraw)",
        "cougar.gauge-range",
        caught_by=("cougar.reply.raw",),
    )
    VERSION_ECHOES_PUMA = defect(
        "version-echoes-puma",
        "VERSION carries the Puma's version word after Cougar's: two data words, not one "
        "(CougarSim._version)",
        "cougar.response.layout",
        caught_by=("cougar.reply.version",),
    )
    FINIT_NO_DATA = defect(
        "finit-no-data",
        "COMINT's table gives the obsolete FINIT no data words, as WINIT has none: its six floats are read "
        "as commands (CougarSim, Comint's table)",
        "cougar.word-link",
        caught_by=("cougar.table1.finit",),
    )
    NOP_UNKNOWN = defect(
        "nop-unknown",
        "COMINT's table starts at WINIT: NOP is an unknown code, so a NOP dumps the buffer and draws an "
        "out-of-sync message (CougarSim, Comint's table)",
        "cougar.nop-resync",
        caught_by=("cougar.comint.nop-resync",),
    )
    IDXS_RESTARTED = defect(
        "idxs-restarted",
        "IDXS is started for every response, in progress or not: each response queued while it is still "
        "sending loses the word that was due next (CougarSim._send)",
        "cougar.idxs-in-progress",
        caught_by=("cougar.link.idxs-burst",),
    )
    GUARD_TYPE_LOW_BYTE = defect(
        "guard-type-low-byte",
        "GUARDS takes a guard's type from bit 7 (a TSTB of the word: the low byte's sign), not from the high "
        "byte (CougarSim._guards)",
        "cougar.guards",
        caught_by=("cougar.guard.trips-once",),
    )
    GUARD_COMPARE_REVERSED = defect(
        "guard-compare-reversed",
        "GUARDM's comparison has its operands the wrong way round (CMPF's order): a guard trips while the "
        "dot product is below tol (CougarSim._guardm)",
        "cougar.guard-trip-threshold",
        caught_by=("cougar.guard.threshold",),
    )
    VERS_BUILT_IN = defect(
        "vers-built-in",
        "VERS answers the version Cougar was built with, not the version word in memory: a DPST there "
        "changes nothing it does (CougarSim._version)",
        "cougar.memory",
        caught_by=("cougar.memory.deposit-examine",),
    )
    GUTS_PART_ON_REENTRY = defect(
        "guts-part-on-reentry",
        "a tick that finds GUTS still running runs COMINT's part on the commands waiting before it returns, "
        "and leaves them in the buffer for the GUTS it interrupted: their answers come twice "
        "(CougarSim.tick)",
        "cougar.guts-reentry",
        "cougar.guts-cost-model",
        caught_by=("cougar.guts.no-nesting", "cougar.guts.reentry"),
    )
    COMINT_BEFORE_GUARDM = defect(
        "comint-before-guardm",
        "GUTS runs COMINT before GUARDM: a guard armed in a tick is tested in that tick (CougarSim.tick)",
        "cougar.guts-order",
        caught_by=("cougar.guts.order",),
    )
    JACOB_ONE_BUFFER = defect(
        "jacob-one-buffer",
        "JACOB writes the new Jacobian into the one buffer the foreground reads, a row per background step, "
        "and never switches buffers: between ticks the foreground may see part of it (Jacob.step)",
        "cougar.jacob-double-buffer",
        caught_by=("cougar.jacob.front-buffer-complete",),
    )
    JACOBIAN_JOINT_SIGN = defect(
        "jacobian-joint-sign",
        "JACOB takes joint 2 as turning the other way round from the arm model: the second column of J "
        "(and so of Jᵀ and P) has the wrong sign (Jacob._jacobian)",
        "cougar.jacob-values",
        caught_by=("cougar.jacob.values",),
    )
    LINK_TICKED_FIRST = defect(
        "link-ticked-first",
        "the link sends a tick's TICKED before the words the tick produced, not after them (CougarEnd)",
        "link.drv11j.framing",
        caught_by=("cougar.link.drv11j-framing",),
    )


@dataclass(frozen=True)
class CougarDefects:
    """How a faulty Cougar departs from Part III of the 1985 guide; the defaults are the guide's."""

    version_code_right: bool = True
    """VERS is answered with response code 8."""
    sends_out_of_sync: bool = True
    """An unknown command code is reported with the out-of-sync message."""
    guard_trips_once: bool = True
    """A guard is disarmed when it trips."""
    conversion_negated: bool = True
    """The force conversion has its -1: the force the robot applies."""
    exmn_whole_count: bool = True
    """EXMN retrieves every word asked for."""
    comint_waits_for_data: bool = True
    """COMINT runs a command only once its data words have all arrived."""
    guardc_disarms: bool = True
    """GUARDC disarms the guard."""
    rst_zeroes_velocities: bool = True
    """RST zeroes the velocities."""
    npr_spring_term: bool = True
    """The compliance equation has its spring term K."""
    filter_cons_in_order: bool = True
    """FILTER weighs the sample with con3 and the filtered value with con4."""
    gravity_follows_angles: bool = True
    """GRAVITY turns the load with the angles SEN or NPR sent."""
    gravity_torque_about_cg: bool = True
    """GRAVITY corrects the torque of the weight about the centre of gravity too."""
    nfv_redoes_gravity: bool = True
    """NFV redoes the gravity model about the new compliance centre."""
    nb_by_rows: bool = True
    """NPR reads NB row after row."""
    jacobian_transpose_stored: bool = True
    """JACOB stores Jᵀ after J."""
    jacobian_joint_signs_right: bool = True
    """JACOB turns every joint the way the arm model does."""
    adc8_sums_then_shifts: bool = True
    """ADC8 adds the terms of the filter's sum before shifting it right by 3."""
    rraw_before_offsets: bool = True
    """RRAW reports the gauges as read, before the offsets are subtracted."""
    guards_on_corrected_force: bool = True
    """GUARDM tests the gravity-corrected force."""
    compliance_on_corrected_force: bool = True
    """NPR's compliance equation uses the gravity-corrected force."""
    npr_commanded_force: bool = True
    """The compliance equation has the commanded force NFC."""
    bji_per_joint: bool = True
    """Each joint's NTD is scaled by its own element of NBJI."""
    rfrc_code_forces: bool = True
    """RFRC is answered with response code 5."""
    rraw_all_gauges: bool = True
    """RRAW reports all eight gauges."""
    rraw_sign_extended: bool = True
    """RRAW reports each reading sign-extended to 16 bits."""
    version_one_word: bool = True
    """VERSION carries one data word, Cougar's version."""
    finit_takes_data: bool = True
    """COMINT's table gives FINIT its six floats."""
    nop_known: bool = True
    """COMINT's table has NOP."""
    idxs_checks_in_progress: bool = True
    """IDXS is started only when it is not already sending."""
    guard_type_in_high_byte: bool = True
    """GUARDS reads a guard's type from the high byte of its first word."""
    guard_compare_ordered: bool = True
    """GUARDM trips a guard when the dot product reaches tol (not when it is below it)."""
    vers_reads_memory: bool = True
    """VERS answers the version word in memory."""
    reentry_returns_at_once: bool = True
    """A tick that finds GUTS still running returns at once."""
    guardm_before_comint: bool = True
    """GUTS runs GUARDM before COMINT."""
    jacob_double_buffered: bool = True
    """JACOB computes into the buffer the foreground does not read and then switches."""


@dataclass(frozen=True)
class LinkDefects:
    """How a faulty Cougar's end of the DRV-11J link departs from ``docs/drv11j.md``; the defaults are
    the link's rules."""

    ends_on_bad_frame: bool = True
    """A frame that cannot be decoded ends the link."""
    ends_on_wrong_side: bool = True
    """A HELLO naming Cougar's own role, or a frame only Cougar sends, ends the link."""
    ends_on_tick_backwards: bool = True
    """A TICK earlier than the one before it ends the link."""
    ends_on_bye: bool = True
    """The Puma's BYE ends the link."""
    refuses_second_puma: bool = True
    """A second Puma connecting while one is linked is sent BYE 'busy'."""
    requires_hello_first: bool = True
    """A first frame that is not HELLO ends the link."""
    checks_version: bool = True
    """A HELLO of another version than 1 ends the link."""
    ticked_after_words: bool = True
    """A tick's TICKED follows the words the tick produced."""


def cougar_defects(faults: Iterable[str]) -> CougarDefects:
    """The behaviours the switches ``faults`` give the simulator."""
    on = parse_faults(faults)
    return CougarDefects(
        version_code_right=CougarFault.WRONG_VERSION_CODE not in on,
        sends_out_of_sync=CougarFault.NO_OUT_OF_SYNC not in on,
        guard_trips_once=CougarFault.GUARD_TRIPS_TWICE not in on,
        conversion_negated=CougarFault.FORCES_WRONG_SIGN not in on,
        exmn_whole_count=CougarFault.EXMN_WRONG_COUNT not in on,
        comint_waits_for_data=CougarFault.COMINT_EXECUTES_PARTIAL not in on,
        guardc_disarms=CougarFault.IGNORES_GUARDC not in on,
        rst_zeroes_velocities=CougarFault.RST_IGNORED not in on,
        npr_spring_term=CougarFault.NPR_IGNORES_K not in on,
        filter_cons_in_order=CougarFault.FILTER_CON_SWAPPED not in on,
        gravity_follows_angles=CougarFault.GRAVITY_FIXED_ORIENTATION not in on,
        gravity_torque_about_cg=CougarFault.GRAVITY_IGNORES_CG not in on,
        nfv_redoes_gravity=CougarFault.NFV_KEEPS_GRAVITY not in on,
        nb_by_rows=CougarFault.NB_TRANSPOSED not in on,
        jacobian_transpose_stored=CougarFault.JACOBIAN_TRANSPOSE_NOT_STORED not in on,
        adc8_sums_then_shifts=CougarFault.FILTER_TRUNCATES_TERMS not in on,
        rraw_before_offsets=CougarFault.RRAW_LESS_OFFSETS not in on,
        guards_on_corrected_force=CougarFault.GUARDS_SENSED_FORCE not in on,
        compliance_on_corrected_force=CougarFault.COMPLIANCE_SENSED_FORCE not in on,
        npr_commanded_force=CougarFault.NPR_IGNORES_FC not in on,
        bji_per_joint=CougarFault.NBJI_FIRST_ONLY not in on,
        rfrc_code_forces=CougarFault.RFRC_NTD_CODE not in on,
        rraw_all_gauges=CougarFault.RRAW_SEVEN_GAUGES not in on,
        rraw_sign_extended=CougarFault.RRAW_UNSIGNED not in on,
        version_one_word=CougarFault.VERSION_ECHOES_PUMA not in on,
        finit_takes_data=CougarFault.FINIT_NO_DATA not in on,
        nop_known=CougarFault.NOP_UNKNOWN not in on,
        idxs_checks_in_progress=CougarFault.IDXS_RESTARTED not in on,
        guard_type_in_high_byte=CougarFault.GUARD_TYPE_LOW_BYTE not in on,
        guard_compare_ordered=CougarFault.GUARD_COMPARE_REVERSED not in on,
        vers_reads_memory=CougarFault.VERS_BUILT_IN not in on,
        reentry_returns_at_once=CougarFault.GUTS_PART_ON_REENTRY not in on,
        guardm_before_comint=CougarFault.COMINT_BEFORE_GUARDM not in on,
        jacob_double_buffered=CougarFault.JACOB_ONE_BUFFER not in on,
        jacobian_joint_signs_right=CougarFault.JACOBIAN_JOINT_SIGN not in on,
    )


def link_defects(faults: Iterable[str]) -> LinkDefects:
    """The behaviours the ``link-*`` switches among ``faults`` give Cougar's end of the link."""
    on = parse_faults(faults)
    return LinkDefects(
        ends_on_bad_frame=CougarFault.LINK_SKIPS_BAD_FRAMES not in on,
        ends_on_wrong_side=CougarFault.LINK_IGNORES_WRONG_SIDE not in on,
        ends_on_tick_backwards=CougarFault.LINK_TICK_BACKWARDS_RUNS not in on,
        ends_on_bye=CougarFault.LINK_IGNORES_BYE not in on,
        refuses_second_puma=CougarFault.LINK_BUSY_SERVES_SECOND not in on,
        requires_hello_first=CougarFault.LINK_HELLO_OPTIONAL not in on,
        checks_version=CougarFault.LINK_IGNORES_VERSION not in on,
        ticked_after_words=CougarFault.LINK_TICKED_FIRST not in on,
    )


def parse_faults(names: Iterable[str]) -> frozenset[CougarFault]:
    """The switches named (blank names skipped); ValueError naming the known ones for an unknown name."""
    chosen = {n.strip() for n in names if n.strip()}
    unknown = sorted(chosen - {f.value for f in CougarFault})
    if unknown:
        known = ", ".join(sorted(f.value for f in CougarFault))
        raise ValueError(f"unknown Cougar fault(s) {unknown}; known: {known}")
    return CougarFault.parse(chosen)
