/* A done verification run's uncertainty and decisions, as the certificate states them
   (server/verify/certificate.py): each compensated point's AP with its U and RP with its U below
   and above, the AP decision against the tolerance, the RP decision against the arm's stated
   repeatability (the cell's repeatability_mm), and a tracker past its calibration's due date. */

/** The decision's sentence, worded as the certificate's verdict_sentence: `figure` (AP, RP)
 *  against `against`, or why there is none (`give` says where to state it); "" for none. */
function decisionText(dec, figure, against, give) {
  if (!dec) return "";
  const tol = dec.tolerance_mm;
  switch (dec.verdict) {
    case "no tolerance":
      return `No ${against} given (${give}): no pass or fail on ${figure}.`;
    case "pass":
      return `${figure} PASS against the ${against} ${tol} mm: every ${figure} plus its U is within it.`;
    case "fail":
      return `${figure} FAIL against the ${against} ${tol} mm: an ${figure} less its U is beyond it.`;
    default:  // not decided: an overdue tracker's figures, or a figure within only one side of U
      return `${figure} NOT DECIDED against the ${against} ${tol} mm: `
        + (dec.tracker_overdue ? `the tracker's calibration was due ${dec.tracker_overdue}.`
          : `a point's ${figure} less its U is within it, but not plus its U.`);
  }
}

/** An RP with its U below and above ("0.0123 −0.0020 / +0.0045"), bare for a run before them. */
function rpText(p) {
  if (p.RP_U_below_mm == null || p.RP_U_above_mm == null) return fmt(p.RP_mm);
  return `${fmt(p.RP_mm)} −${fmt(p.RP_U_below_mm)} / +${fmt(p.RP_U_above_mm)}`;
}

/** The uncertainty block's nodes of a verification report (the API's verification.json). */
function verificationUncertainty(r) {
  const unc = r.uncertainty || {};
  const nodes = [];
  if (r.tracker_overdue) {
    nodes.push(Object.assign(document.createElement("p"), {
      id: "v-overdue", className: "warn",
      textContent: `Tracker calibration overdue (due ${r.tracker_overdue}): this run cannot pass.`,
    }));
  }
  const table = makeTable("v-uncertainty", ["point", "AP after ± U / mm", "RP after −U / +U / mm"],
    r.after.points.map((p) => [
      p.point, p.AP_U_mm == null ? fmt(p.AP_mm) : `${fmt(p.AP_mm)} ± ${fmt(p.AP_U_mm)}`, rpText(p)]));
  table.createCaption().textContent = "each compensated test point with its uncertainty (95 %)";
  nodes.push(table);
  const said = [
    ["v-ap-decision", unc.decision,
      decisionText(unc.decision, "AP", "tolerance", "the cell's tolerance_mm or the model's")],
    ["v-rp-decision", unc.rp_decision,
      decisionText(unc.rp_decision, "RP", "arm's stated repeatability", "the cell's repeatability_mm")],
  ];
  said.forEach(([id, dec, text]) => {
    if (!text) return;
    // the verdict in bold, as the certificate's: "AP NOT DECIDED" then its reason
    const head = text.match(/^(AP|RP) (PASS|FAIL|NOT DECIDED)/);
    const p = Object.assign(document.createElement("p"), { id });
    if (head) p.appendChild(document.createElement("b")).textContent = head[0];
    p.append(head ? text.slice(head[0].length) : text);
    p.className = `v-decision v-${dec.verdict.replace(" ", "-")}`;
    p.title = `decision rule: ${dec.rule}`;
    nodes.push(p);
  });
  const notes = [unc.ap_u, unc.rp_u].filter(Boolean);
  said.forEach(([, dec]) => { if (dec) notes.push(`Decision rule: ${dec.rule}.`); });
  notes.forEach((n) => nodes.push(Object.assign(document.createElement("p"),
    { className: "muted v-note", textContent: n.endsWith(".") ? n : `${n}.` })));
  return nodes;
}
