import { tokenizeGcode } from './access';

/**
 * What an operator's Duet job may contain (Node-safe, pure). An operator may start a job file of
 * `0:/gcodes/` (M32, M37), and a job runs every line of it with the firmware's full authority, so
 * an uploaded file holding `M551 P"…"` (password) or `M98 P"…"` (a macro) would do through the job
 * what the console refuses an operator directly. The gateway reads the file before it lets an
 * operator start it (`gateway.ts`), and refuses the start — naming the file, the line and the code
 * — when the file holds a code below that needs a supervisor, or a line it cannot read for certain
 * (tokenised as the console's G-code classification does, `tokenizeGcode`: meta commands such as
 * `echo >"file"`, `if`, `while` are not read, so they need a supervisor too). A supervisor's start
 * is not checked. Ordinary job content (moves, heaters, fans, tools, homing, extrusion, limits set
 * for the job, messages) passes.
 */

/** Codes an operator's job may not contain, with why (the same words in the refusal). */
export const JOB_FORBIDDEN: Readonly<Record<string, string>> = {
  M98: 'runs a macro (arbitrary G-code)',
  M23: 'selects another file (not checked)',
  M32: 'starts another file (not checked)',
  M37: 'simulates another file (not checked)',
  M28: 'writes a file',
  M29: 'writes a file',
  M30: 'deletes a file',
  M470: 'creates a folder',
  M471: 'renames a file',
  M559: 'writes a configuration file',
  M560: 'writes a web file',
  M929: 'writes a log file',
  M500: 'saves settings (config-override.g)',
  M501: 'loads stored settings',
  M502: 'resets settings',
  M505: 'changes the configuration folder',
  M540: 'sets the network MAC address',
  M550: 'sets the machine name',
  M551: 'sets the password',
  M552: 'changes the network',
  M553: 'changes the network',
  M554: 'changes the network',
  M586: 'changes the network protocols',
  M587: 'stores WiFi credentials',
  M588: 'forgets WiFi credentials',
  M589: 'configures the access point',
  M575: 'configures a serial port',
  M143: 'changes a heater’s temperature limit',
  M570: 'changes heater fault detection',
  M950: 'remaps a heater, fan or pin',
  M308: 'changes a temperature sensor',
  M997: 'updates the firmware',
  M999: 'resets the board',
};

export interface JobFinding {
  /** 1-based line of the file. */
  line: number;
  code: string | null;
  why: string;
}

/** The longest line read (RRF's own G-code buffer is far shorter): a longer one is not checked. */
export const MAX_JOB_LINE = 4096;

/**
 * An unquoted M117 message (`M117 Layer 1`) as slicers write it: RepRapFirmware reads the rest of
 * the line as the message but starts a new command at a G or M with a digit, so only a text
 * without one (nor a quote, brace or control character) is taken as a message.
 */
// eslint-disable-next-line no-control-regex
const M117_TEXT = /^\s*(?:[Nn]\d+\s+)?[Mm]0*117(?:\s+[^;"{}'\u0000-\u001f\u007f]*)?(?:;.*)?$/;

function lineFinding(line: string, n: number): JobFinding | null {
  if (line.length > MAX_JOB_LINE) return { line: n, code: null, why: 'a line too long to check' };
  const t = tokenizeGcode(line);
  if (!t.ok) {
    if (M117_TEXT.test(line) && !/[GgMmTt]\d/.test(line.replace(/^\s*(?:[Nn]\d+\s+)?[Mm]0*117/, '')))
      return null;
    return { line: n, code: null, why: `a line the gateway cannot check (${t.reason})` };
  }
  for (const c of t.commands) {
    const why = JOB_FORBIDDEN[c.word];
    if (why !== undefined) return { line: n, code: c.word, why };
  }
  return null;
}

/** Reads a job file as it streams (any chunking), stopping at the first finding. */
export class JobScanner {
  private readonly decoder = new TextDecoder('utf-8', { fatal: false });
  private rest = '';
  private lineNo = 0;
  finding: JobFinding | null = null;
  bytes = 0;

  /** Feeds a chunk; false once a finding stops the scan. */
  push(chunk: Uint8Array): boolean {
    if (this.finding) return false;
    this.bytes += chunk.byteLength;
    this.rest += this.decoder.decode(chunk, { stream: true });
    let at = this.rest.indexOf('\n');
    while (at >= 0) {
      const line = this.rest.slice(0, at).replace(/\r$/, '');
      this.rest = this.rest.slice(at + 1);
      this.lineNo++;
      this.finding = lineFinding(line, this.lineNo);
      if (this.finding) return false;
      at = this.rest.indexOf('\n');
    }
    if (this.rest.length > MAX_JOB_LINE) {
      this.finding = { line: this.lineNo + 1, code: null, why: 'a line too long to check' };
      return false;
    }
    return true;
  }

  /** The end of the file: its last line, then the verdict (null: an operator may start it). */
  end(): JobFinding | null {
    if (this.finding) return this.finding;
    this.rest += this.decoder.decode();
    if (this.rest !== '') {
      this.lineNo++;
      this.finding = lineFinding(this.rest.replace(/\r$/, ''), this.lineNo);
    }
    return this.finding;
  }
}

/** A whole file at once (tests, small bodies). */
export function scanJob(text: string): JobFinding | null {
  const s = new JobScanner();
  s.push(new TextEncoder().encode(text));
  return s.end();
}

/** The job files the M32/M37 of a G-code body start (each quoted file; none: no start). */
export function startedJobFiles(body: string): string[] {
  const t = tokenizeGcode(body);
  if (!t.ok) return [];
  const out: string[] = [];
  for (const c of t.commands) {
    if (c.word !== 'M32' && c.word !== 'M37') continue;
    for (const p of c.params) if (p.kind === 'string') out.push(p.text);
  }
  return out;
}
