import { operator, supervisor, type AccessDecision } from '../../fleet/access';
import { CONTROL, isJobFile, JOBS_DIR } from './paths';

/**
 * Which G-code bodies are operator work (`classifyCode`): job control (M0, M24, M25, M32/M37 of an
 * absolute job file, M112, M999 right after M112, M292 with P/S/R as the console sends them);
 * everything else needs a supervisor. The rules and reasons: README.md, "G-code classification".
 */

export interface GcodeParam {
  /** Upper-case parameter letter; null for the unprecedented string of M23/M28/M30/M32/M36/M117. */
  letter: string | null;
  kind: 'number' | 'string' | 'expression';
  /** The number as written, the string with `""` unescaped, or the expression with its braces. */
  text: string;
}

export interface GcodeCommand {
  /** "M112", "G28.2" (leading zeros dropped: M00 → M0) */
  word: string;
  params: GcodeParam[];
  /** 0-based line of the body. */
  line: number;
}

export type GcodeTokens =
  { ok: true; commands: GcodeCommand[] } | { ok: false; reason: string; line: number };

/** Codes whose parameter is the rest of the line (DSF `unprecedentedParameter`). */
const UNPRECEDENTED = new Set(['M23', 'M28', 'M30', 'M32', 'M36', 'M117']);
const NUMBER = /^[-+]?(?:\d+(?:\.\d*)?|\.\d+)/;

class Uncertain extends Error {}

/**
 * Splits a G-code body into commands the way RepRapFirmware (`StringParser`) and DSF's code parser
 * both read it, or refuses (`ok: false`, not classified) wherever the two could read it differently
 * or it holds anything a job-control command would not. What is accepted and refused: README.md,
 * "G-code classification".
 */
export function tokenizeGcode(body: string): GcodeTokens {
  const lines = body.split('\n');
  const commands: GcodeCommand[] = [];
  for (let li = 0; li < lines.length; li++) {
    let line = lines[li] ?? '';
    if (line.endsWith('\r')) line = line.slice(0, -1);
    try {
      commands.push(...tokenizeLine(line, li));
    } catch (e) {
      if (e instanceof Uncertain) return { ok: false, reason: e.message, line: li };
      throw e;
    }
  }
  return { ok: true, commands };
}

function tokenizeLine(line: string, li: number): GcodeCommand[] {
  if (CONTROL.test(line.replace(/\t/g, ' '))) throw new Uncertain('a control character');
  const out: GcodeCommand[] = [];
  let i = 0;
  const blank = (c: string | undefined) => c === ' ' || c === '\t';
  const skipBlanks = () => {
    while (blank(line[i])) i++;
  };
  /** After a code or value: a blank, a comment or the end of the line. */
  const mustEndToken = (what: string) => {
    const c = line[i];
    if (c !== undefined && !blank(c) && c !== ';') throw new Uncertain(`"${c}" right after ${what}`);
  };
  const atEnd = () => i >= line.length || line[i] === ';';

  skipBlanks();
  if (atEnd()) return out;
  const ln = /^[Nn]\d+/.exec(line.slice(i));
  if (ln) {
    i += ln[0].length;
    if (!blank(line[i])) throw new Uncertain('a line number not followed by a blank');
    skipBlanks();
    if (atEnd()) return out;
  }

  while (!atEnd()) {
    const code = /^([GgMmTt])(\d+)(?:\.(\d+))?/.exec(line.slice(i));
    if (!code) throw new Uncertain(`not a G/M/T command (meta command or unknown text) at column ${i + 1}`);
    const word = `${(code[1] ?? '').toUpperCase()}${Number(code[2])}${code[3] !== undefined ? `.${code[3]}` : ''}`;
    i += code[0].length;
    mustEndToken(word);
    const cmd: GcodeCommand = { word, params: [], line: li };
    out.push(cmd);
    const seen = new Set<string>();
    for (;;) {
      skipBlanks();
      if (atEnd()) break;
      const c = line[i] ?? '';
      if (UNPRECEDENTED.has(word)) {
        // DSF reads the rest of the line as the file name unless it is quoted; RRF stops at G/M.
        if (c !== '"') throw new Uncertain(`${word} takes one quoted file name`);
        cmd.params.push({ letter: null, kind: 'string', text: quoted() });
        mustEndToken(`the ${word} string`);
        skipBlanks();
        if (!atEnd()) throw new Uncertain(`text after the ${word} file name`);
        break;
      }
      // A G or M with a number starts the next command on the same line (RRF and DSF agree
      // once a blank separates them).
      if (/^[GgMm]\d/.test(line.slice(i, i + 2))) break;
      if (!/^[A-Za-z]$/.test(c)) throw new Uncertain(`"${c}" where a parameter letter belongs`);
      const letter = c.toUpperCase();
      if (seen.has(letter)) throw new Uncertain(`${word} repeats ${letter}`);
      seen.add(letter);
      i++;
      const v = line[i];
      if (v === '"') cmd.params.push({ letter, kind: 'string', text: quoted() });
      else if (v === '{') cmd.params.push({ letter, kind: 'expression', text: expression() });
      else {
        const num = NUMBER.exec(line.slice(i));
        if (!num) throw new Uncertain(`${letter} without a number, string or expression`);
        i += num[0].length;
        cmd.params.push({ letter, kind: 'number', text: num[0] });
      }
      mustEndToken(`${word} ${letter}`);
    }
  }
  return out;

  /** A double-quoted string at `i`; `""` is one quote. Leaves `i` after the closing quote. */
  function quoted(): string {
    let s = '';
    i++;
    for (;;) {
      const c = line[i];
      if (c === undefined) throw new Uncertain('an unterminated string');
      i++;
      if (c === '"') {
        if (line[i] === '"') {
          s += '"';
          i++;
          continue;
        }
        return s;
      }
      if (c === "'") throw new Uncertain("' in a string (RRF and DSF lower-case the next character)");
      s += c;
    }
  }

  /** A `{…}` expression at `i`, braces balanced, strings skipped as RRF skips them. */
  function expression(): string {
    const start = i;
    let depth = 0;
    for (;;) {
      const c = line[i];
      if (c === undefined) throw new Uncertain('an unterminated expression');
      if (c === '"') {
        const s = quoted();
        if (/[{}()]/.test(s))
          throw new Uncertain('a string holding {}() in an expression (DSF does not skip strings there)');
        continue;
      }
      if (c === ';') throw new Uncertain('; inside an expression');
      if (c === "'") throw new Uncertain("' inside an expression");
      i++;
      if (c === '{') depth++;
      if (c === '}' && --depth === 0) return line.slice(start, i);
    }
  }
}

const INTEGER = /^[-+]?\d+$/;
const R_NUMBER = /^\{[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?\}$/;
/** `{"text"}`: one string literal, nothing else (no `{}()'` inside; the tokenizer checked quotes). */
const R_STRING = /^\{"(?:[^"{}()']|"")*"\}$/;

/** Why a command is not operator work, or null when it is. */
function notOperator(cmd: GcodeCommand, previous: GcodeCommand | undefined): string | null {
  const only = (...letters: string[]) =>
    cmd.params.every((p) => p.letter !== null && letters.includes(p.letter));
  switch (cmd.word) {
    case 'M0':
    case 'M24':
    case 'M25':
    case 'M112':
      return cmd.params.length === 0 ? null : `${cmd.word} with parameters`;
    case 'M999':
      if (previous?.word !== 'M112') return 'M999 (board reset) other than right after M112';
      return cmd.params.length === 0 ? null : 'M999 with parameters';
    case 'M292': {
      if (!only('P', 'S', 'R')) return 'M292 with other parameters';
      for (const p of cmd.params) {
        if (p.letter === 'R') {
          if (p.kind !== 'expression' || !(R_NUMBER.test(p.text) || R_STRING.test(p.text)))
            return 'M292 with an R other than a number or a text';
        } else if (p.kind !== 'number' || !INTEGER.test(p.text)) return `M292 with a non-integer ${p.letter}`;
      }
      return null;
    }
    case 'M32':
    case 'M37': {
      const [p] = cmd.params;
      const letter = cmd.word === 'M32' ? null : 'P';
      if (cmd.params.length !== 1 || !p || p.letter !== letter || p.kind !== 'string')
        return `${cmd.word} without exactly one quoted file`;
      return isAbsolute(p.text) && isJobFile(p.text)
        ? null
        : `${cmd.word} of ${p.text} (not a job file in ${JOBS_DIR})`;
    }
    default:
      return cmd.word;
  }
}

/** M32/M37 resolve a relative name against the G-code folder of the moment: only absolute names. */
function isAbsolute(path: string): boolean {
  const p = path.replace(/\\/g, '/');
  return /^\d+:/.test(p) || p.startsWith('/');
}

export function classifyCode(body: string): AccessDecision {
  const t = tokenizeGcode(body);
  if (!t.ok)
    return supervisor(
      `send G-code the gateway cannot classify for certain (line ${t.line + 1}: ${t.reason})`,
    );
  if (t.commands.length === 0) return supervisor('send an empty G-code request');
  for (let k = 0; k < t.commands.length; k++) {
    const cmd = t.commands[k];
    if (!cmd) continue;
    const why = notOperator(cmd, t.commands[k - 1]);
    if (why !== null) return supervisor(`send G-code ${why}`);
  }
  const words = new Set(t.commands.map((c) => c.word));
  // Which console command this body is (the audit's commandId, the history's attribution): the
  // strongest job word in it, whatever the page says it sent.
  const job = JOB_WORDS.find(([w]) => words.has(w));
  return operator(`send ${[...words].join(', ')}`, job?.[1]);
}

/** Job words by strength: a body with M112 is an emergency stop, whatever else it holds. */
const JOB_WORDS: ReadonlyArray<readonly [string, string]> = [
  ['M112', 'duet.estop'],
  ['M0', 'duet.cancel'],
  ['M32', 'duet.start'],
  ['M37', 'duet.simulate'],
  ['M25', 'duet.pause'],
  ['M24', 'duet.resume'],
];
