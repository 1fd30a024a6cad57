// @vitest-environment happy-dom
import { cleanup, fireEvent, render, screen } from '@testing-library/react';
import { afterEach, describe, expect, it, vi } from 'vitest';
import { axisName, CsvButton } from './common';

afterEach(() => {
  cleanup();
  vi.restoreAllMocks();
});

describe('CsvButton', () => {
  it('downloads the table through the shared writer: BOM, defused controller text, numbers as numbers', async () => {
    const blobs: Blob[] = [];
    vi.spyOn(URL, 'createObjectURL').mockImplementation((b) => {
      blobs.push(b as Blob);
      return 'blob:t';
    });
    vi.spyOn(URL, 'revokeObjectURL').mockImplementation(() => undefined);
    const names: string[] = [];
    vi.spyOn(HTMLAnchorElement.prototype, 'click').mockImplementation(function (this: HTMLAnchorElement) {
      names.push(this.download);
    });
    render(
      <CsvButton
        name="touchcut-programs-x"
        columns={[
          { label: 'program', value: (r: { p: string; n: number }) => r.p },
          { label: 'runs', value: (r) => r.n },
        ]}
        rows={[
          { p: '=HYPERLINK("http://evil.example")', n: -2 },
          { p: 'bracket, v2', n: 3 },
        ]}
      />,
    );
    fireEvent.click(screen.getByTestId('csv-touchcut-programs-x'));
    expect(names).toEqual(['touchcut-programs-x.csv']);
    expect(blobs[0]!.type).toBe('text/csv;charset=utf-8');
    const bytes = new Uint8Array(await blobs[0]!.arrayBuffer());
    expect([...bytes.slice(0, 3)]).toEqual([0xef, 0xbb, 0xbf]);
    expect(new TextDecoder().decode(bytes)).toBe(
      `program,runs\r\n"'=HYPERLINK(""http://evil.example"")",-2\r\n"bracket, v2",3\r\n`,
    );
  });

  it('is disabled for an empty table', () => {
    render(<CsvButton name="empty" columns={[{ label: 'a', value: () => 1 }]} rows={[]} />);
    expect((screen.getByTestId('csv-empty') as HTMLButtonElement).disabled).toBe(true);
  });
});

describe('axisName', () => {
  it("names TouchCut's axes as people say them", () => {
    expect(axisName('axisLong')).toBe('Long axis');
    expect(axisName('axisShort')).toBe('Short axis');
    expect(axisName('axisTorch')).toBe('Torch axis');
    expect(axisName('axisBevelHead')).toBe('Bevel head axis');
    expect(axisName('Gantry')).toBe('Gantry');
    expect(axisName(undefined, '10')).toBe('Axis 10');
  });
});
