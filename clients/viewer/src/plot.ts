// The live force-depth plot: the frames' (indentation, contact force) against Hertz's
// rigid sphere on an elastic half-space, F = 4/3 E* sqrt(R) d^(3/2), E* = E / (1 - nu^2)
// (docs/physics.md (3.1), (3.2)), and the scene's converged finite-block reference where
// the server has one (its depths with their uncertainty as bars), on a 2-D canvas.
export function hertzForce(depth: number, radius: number, youngModulus: number, poissonRatio: number): number {
  if (depth <= 0) return 0;
  const effective = youngModulus / (1 - poissonRatio * poissonRatio);
  return (4 / 3) * effective * Math.sqrt(radius) * Math.pow(depth, 1.5);
}

export class ForceDepthPlot {
  private depths = new Float64Array(4000);
  private forces = new Float64Array(4000);
  private count = 0;
  private next = 0;
  private dMax = 0;
  private fMax = 0;

  constructor(
    private canvas: HTMLCanvasElement,
    private radius: number,
    private youngModulus: number,
    private poissonRatio: number,
    private reference: { forces: Float64Array; indentation: Float64Array; uncertainty: Float64Array } = {
      forces: new Float64Array(0),
      indentation: new Float64Array(0),
      uncertainty: new Float64Array(0),
    },
  ) {
    // Start with the range of d/R = 0.1 so that Hertz is visible before any press.
    this.dMax = 0.1 * radius;
    this.fMax = hertzForce(this.dMax, radius, youngModulus, poissonRatio);
    // ... and the reference's range when there is one.
    for (let k = 0; k < reference.forces.length; k++) {
      this.dMax = Math.max(this.dMax, 1.05 * (reference.indentation[k] + reference.uncertainty[k]));
      this.fMax = Math.max(this.fMax, 1.05 * reference.forces[k]);
    }
  }

  add(depth: number, force: number): void {
    this.depths[this.next] = depth;
    this.forces[this.next] = force;
    this.next = (this.next + 1) % this.depths.length;
    this.count = Math.min(this.count + 1, this.depths.length);
    this.dMax = Math.max(this.dMax, 1.1 * depth);
    this.fMax = Math.max(this.fMax, 1.1 * force);
  }

  clear(): void {
    this.count = 0;
    this.next = 0;
  }

  draw(): void {
    const c = this.canvas;
    const w = (c.width = c.clientWidth || 360);
    const h = (c.height = c.clientHeight || 220);
    const g = c.getContext("2d")!;
    const left = 48, bottom = 30, top = 10, right = 10;
    const X = (d: number) => left + ((w - left - right) * d) / this.dMax;
    const Y = (f: number) => h - bottom - ((h - bottom - top) * f) / this.fMax;
    g.fillStyle = "#15171c";
    g.fillRect(0, 0, w, h);
    g.strokeStyle = "#444a55";
    g.strokeRect(left, top, w - left - right, h - top - bottom);
    g.fillStyle = "#aab";
    g.font = "11px sans-serif";
    g.fillText(`${(1000 * this.dMax).toPrecision(3)} mm`, w - right - 60, h - 12);
    g.fillText("indentation d", left + 4, h - 12);
    g.fillText(`${this.fMax.toPrecision(3)} N`, 2, top + 10);
    g.fillText("F", 2, h / 2);
    // Hertz
    g.strokeStyle = "#7fb3ff";
    g.beginPath();
    for (let i = 0; i <= 100; i++) {
      const d = (this.dMax * i) / 100;
      const f = hertzForce(d, this.radius, this.youngModulus, this.poissonRatio);
      if (i === 0) g.moveTo(X(d), Y(f));
      else g.lineTo(X(d), Y(f));
    }
    g.stroke();
    // The reference: points with their depth uncertainty, inside the plotted range
    g.strokeStyle = g.fillStyle = "#66dd88";
    for (let k = 0; k < this.reference.forces.length; k++) {
      const f = this.reference.forces[k], d = this.reference.indentation[k], u = this.reference.uncertainty[k];
      if (d > this.dMax || f > this.fMax) continue;
      g.beginPath();
      g.moveTo(X(d - u), Y(f));
      g.lineTo(X(d + u), Y(f));
      g.stroke();
      g.fillRect(X(d) - 2.5, Y(f) - 2.5, 5, 5);
    }
    // Frames, newest brightest
    for (let k = 0; k < this.count; k++) {
      const i = (this.next - this.count + k + this.depths.length) % this.depths.length;
      g.fillStyle = k > this.count - 20 ? "#ffcc44" : "#c08a2a";
      g.fillRect(X(this.depths[i]) - 1.5, Y(this.forces[i]) - 1.5, 3, 3);
    }
    g.fillStyle = "#7fb3ff";
    g.fillText("Hertz", w - right - 40, top + 12);
    g.fillStyle = "#ffcc44";
    g.fillText("simulation", w - right - 64, top + 26);
    if (this.reference.forces.length > 0) {
      g.fillStyle = "#66dd88";
      g.fillText("reference", w - right - 60, top + 40);
    }
  }
}
